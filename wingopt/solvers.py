"""One status vocabulary for every optimisation backend (CVXPY/Clarabel/OSQP, CasADi/IPOPT).

Backends report their own status strings; :func:`status_from` maps them to
:class:`SolveStatus`, and :func:`require_success` turns a failure into a
:class:`~wingopt.errors.SolverError` that names the backend, its raw status and a hint.
"""

from __future__ import annotations

import enum

from wingopt.errors import SolverError

__all__ = ["SolveStatus", "status_from", "require_success", "BACKENDS"]

BACKENDS = ("clarabel", "osqp", "ipopt", "casadi-qp")


class SolveStatus(enum.Enum):
    OPTIMAL = "optimal"
    OPTIMAL_INACCURATE = "optimal_inaccurate"
    INFEASIBLE = "infeasible"
    UNBOUNDED = "unbounded"
    MAX_ITERATIONS = "max_iterations"
    NUMERICAL_ERROR = "numerical_error"
    UNKNOWN = "unknown"

    @property
    def ok(self) -> bool:
        """Whether the answer can be used (accurate, or inaccurate but reported as a solution)."""
        return self in (SolveStatus.OPTIMAL, SolveStatus.OPTIMAL_INACCURATE)


_HINTS = {
    SolveStatus.INFEASIBLE: "the constraints cannot all hold: check voltage/slew limits and bounds",
    SolveStatus.UNBOUNDED: "the cost is unbounded below: check that the weights are positive definite",
    SolveStatus.MAX_ITERATIONS: "raise the iteration limit or loosen the tolerances",
    SolveStatus.NUMERICAL_ERROR: "the problem may be badly scaled: check units and weights, or try another backend",
    SolveStatus.UNKNOWN: "try another backend (--solver)",
}


def status_from(backend: str, raw: str) -> SolveStatus:
    """Map a backend's raw status string to :class:`SolveStatus`."""
    s = str(raw).strip().lower().replace(" ", "_")
    if s in ("optimal", "solved", "solve_succeeded", "success"):
        return SolveStatus.OPTIMAL
    if s in ("optimal_inaccurate", "solved_inaccurate", "solved_to_acceptable_level", "almostsolved"):
        return SolveStatus.OPTIMAL_INACCURATE
    # A dual-infeasible QP is primal unbounded: test it before plain infeasibility.
    if "unbounded" in s or "dual_infeasible" in s:
        return SolveStatus.UNBOUNDED
    if "infeasible" in s:
        return SolveStatus.INFEASIBLE
    if "max" in s and "iter" in s or s in ("maximum_iterations_exceeded", "maxiterations", "max_iter_reached"):
        return SolveStatus.MAX_ITERATIONS
    if any(k in s for k in ("numerical", "error", "nan", "insufficient", "invalid")):
        return SolveStatus.NUMERICAL_ERROR
    return SolveStatus.UNKNOWN


def require_success(backend: str, raw: str, hint: str | None = None) -> SolveStatus:
    """The mapped status, or a :class:`SolverError` naming ``backend``, ``raw`` status and a hint."""
    status = status_from(backend, raw)
    if not status.ok:
        raise SolverError(backend, str(raw), hint or _HINTS.get(status, ""))
    return status
