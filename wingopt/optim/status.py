"""One status vocabulary and one failure path for every optimisation backend.

Backends report their own status strings (CVXPY/Clarabel/OSQP, CasADi/IPOPT/qpOASES, DAQP, PIQP,
ProxQP); :func:`status_from` maps them to :class:`SolveStatus`, and :func:`require_success` /
:func:`fail` turn a failure into a :class:`~wingopt.errors.SolverError` that names the backend,
its raw status and a hint (what to try in the context that called the solver: the morphing QP or
the MHE window). This module names statuses only; the solver names are in
:mod:`wingopt.optim.registry`, the flags that choose them in the CLI.
"""

from __future__ import annotations

import enum

from wingopt.errors import SolverError

__all__ = ["SolveStatus", "status_from", "require_success", "fail", "hint", "HINTS", "CONTEXT_HINTS"]


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


HINTS = {
    SolveStatus.INFEASIBLE: "the constraints cannot all hold: check voltage/slew limits and bounds",
    SolveStatus.UNBOUNDED: "the cost is unbounded below: check that the weights are positive definite",
    SolveStatus.MAX_ITERATIONS: "raise the iteration limit or loosen the tolerances",
    SolveStatus.NUMERICAL_ERROR: "the problem may be badly scaled: check units and weights, or try another backend",
    SolveStatus.UNKNOWN: "try another backend",
}
"""What to try, by status (used when the caller gives no context)."""

CONTEXT_HINTS = {
    "qp": "try another QP backend, a shorter horizon, or wider limits",
    "mhe": "try another window solver, a longer window, or check the data's units",
}
"""What to try, by the caller's context. The context travels with the error
(:attr:`SolverError.context <wingopt.errors.SolverError>`), so that a front end can name the
setting that picks another solver (the CLI: ``--solver``)."""


def status_from(backend: str, raw) -> SolveStatus:
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
    failures = ("numerical", "numerics", "error", "nan", "insufficient", "invalid", "cycling", "nonconvex")
    if any(k in s for k in failures):
        return SolveStatus.NUMERICAL_ERROR
    return SolveStatus.UNKNOWN


def hint(context: str | None = None, status: SolveStatus | None = None) -> str:
    """The hint of a failure: by context (``"qp"``, ``"mhe"``) if given, else by status."""
    if context is not None:
        return CONTEXT_HINTS.get(context, context)
    return HINTS.get(status, "") if status is not None else ""


def fail(backend: str, raw, context: str | None = None, status: SolveStatus | None = None) -> SolverError:
    """The :class:`SolverError` of a failed solve (to ``raise``): backend, raw status, hint and context."""
    status = status if status is not None else status_from(backend, raw)
    return SolverError(backend, str(raw), hint(context, status), context=context)


def require_success(backend: str, raw, hint: str | None = None) -> SolveStatus:
    """The mapped status, or a :class:`SolverError` naming ``backend``, ``raw`` status and a hint."""
    status = status_from(backend, raw)
    if not status.ok:
        raise SolverError(backend, str(raw), hint or HINTS.get(status, ""))
    return status
