"""Parametric convex QPs and the backends that solve them (CVXPY+Clarabel/OSQP, CasADi).

Every QP of the morphing controllers has the same canonical form, with a parameter vector ``p``
(the estimated state and the previous input) entering the linear term and the constraint bounds
affinely::

    min_v  1/2 v^T H v + (q0 + Qp p)^T v + c(p)
    s.t.   A_eq v  = b0 + Bp p
           l0 + Lp p <= A_in v <= u0 + Up p

``H`` and both constraint matrices are constant, so a backend is *built once* and then re-solved
for each new ``p``: CVXPY with a ``Parameter`` (DPP: the canonicalisation is cached and a re-solve
only maps ``p`` to the solver data; OSQP keeps its factorisation and is warm-started), CasADi
with one ``conic`` (QP plugin) or ``nlpsol`` (IPOPT) function. All report
:class:`wingopt.solvers.SolveStatus`, and a failure raises :class:`~wingopt.errors.SolverError`
naming the backend and its own status. The objective a backend reports is evaluated by
:meth:`ParametricQP.objective` on its solution, the same function for every backend.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from wingopt.errors import InputError, SolverError
from wingopt.solvers import SolveStatus, status_from

__all__ = ["ParametricQP", "QPSolution", "QPBackend", "make_backend", "BACKENDS"]

log = logging.getLogger(__name__)

BACKENDS = ("clarabel", "osqp", "ipopt", "casadi-qp")
"""Names accepted by :func:`make_backend` (the package-wide names of :data:`wingopt.solvers.BACKENDS`)."""

_HINT = "try another QP backend (--solver clarabel|osqp|ipopt|casadi-qp), a shorter horizon, or wider limits"


def _as_sparse(a, shape) -> sp.csc_matrix:
    if a is None:
        return sp.csc_matrix(shape)
    return sp.csc_matrix(a)


@dataclass(frozen=True, eq=False)
class ParametricQP:
    """``min 1/2 v'Hv + q(p)'v + c(p)`` s.t. ``A_eq v = b(p)``, ``l(p) <= A_in v <= u(p)``.

    All affine maps are stored as ``(constant, matrix)`` pairs: ``q(p) = q0 + Qp p`` and so on.
    ``c(p) = c0 + cp' p + 1/2 p' Cpp p`` is the constant part of the objective (it does not change
    the minimiser; it makes the reported objective the true cost).
    """

    H: sp.csc_matrix
    q0: np.ndarray
    Qp: sp.csc_matrix
    A_in: sp.csc_matrix
    l0: np.ndarray
    Lp: sp.csc_matrix
    u0: np.ndarray
    Up: sp.csc_matrix
    A_eq: sp.csc_matrix | None = None
    b0: np.ndarray | None = None
    Bp: sp.csc_matrix | None = None
    c0: float = 0.0
    cp: np.ndarray | None = None
    Cpp: np.ndarray | None = None
    names: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        nv = self.H.shape[0]
        if self.H.shape != (nv, nv) or self.A_in.shape[1] != nv:
            raise InputError(f"QP: H {self.H.shape} and A_in {self.A_in.shape} do not agree")
        if self.A_eq is not None and self.A_eq.shape[1] != nv:
            raise InputError(f"QP: A_eq {self.A_eq.shape} has the wrong number of columns (expected {nv})")

    @property
    def n_variables(self) -> int:
        return self.H.shape[0]

    @property
    def n_parameters(self) -> int:
        return self.Qp.shape[1]

    @property
    def n_eq(self) -> int:
        return 0 if self.A_eq is None else self.A_eq.shape[0]

    def q(self, p: np.ndarray) -> np.ndarray:
        return self.q0 + self.Qp @ p

    def lower(self, p: np.ndarray) -> np.ndarray:
        return self.l0 + self.Lp @ p

    def upper(self, p: np.ndarray) -> np.ndarray:
        return self.u0 + self.Up @ p

    def b(self, p: np.ndarray) -> np.ndarray:
        return self.b0 + self.Bp @ p

    def constant(self, p: np.ndarray) -> float:
        c = self.c0
        if self.cp is not None:
            c += float(self.cp @ p)
        if self.Cpp is not None:
            c += 0.5 * float(p @ (self.Cpp @ p))
        return c

    def objective(self, v: np.ndarray, p: np.ndarray) -> float:
        """The full cost at ``v`` (same evaluation for every backend)."""
        return float(0.5 * v @ (self.H @ v) + self.q(p) @ v + self.constant(p))

    def violation(self, v: np.ndarray, p: np.ndarray) -> float:
        """Largest constraint violation at ``v`` (in the QP's scaled units)."""
        Av = self.A_in @ v
        viol = max(float(np.max(self.lower(p) - Av, initial=0.0)), float(np.max(Av - self.upper(p), initial=0.0)))
        if self.A_eq is not None:
            viol = max(viol, float(np.max(np.abs(self.A_eq @ v - self.b(p)), initial=0.0)))
        return viol


@dataclass(frozen=True)
class QPSolution:
    """Result of one solve: minimiser ``v``, true objective, status, backend's own status, timing."""

    v: np.ndarray
    objective: float
    status: SolveStatus
    raw_status: str
    iterations: int
    backend: str
    seconds: float


class QPBackend:
    """Interface: built once for a :class:`ParametricQP`, then ``solve(p, warm=None)`` per step."""

    name = "base"

    def __init__(self, qp: ParametricQP, tolerance: float = 1e-8, max_iterations: int = 10000) -> None:
        self.qp = qp
        self.tolerance = float(tolerance)
        self.max_iterations = int(max_iterations)
        t0 = time.perf_counter()
        self._build()
        self.build_seconds = time.perf_counter() - t0
        self.solves = 0

    def _build(self) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def _solve(self, p: np.ndarray, warm: np.ndarray | None) -> tuple[np.ndarray | None, str, SolveStatus, int]:
        raise NotImplementedError  # pragma: no cover - interface

    def solve(self, p: np.ndarray, warm: np.ndarray | None = None) -> QPSolution:
        """Minimiser for parameter ``p``; raises :class:`SolverError` when the backend fails."""
        p = np.asarray(p, dtype=float)
        if p.shape != (self.qp.n_parameters,):
            raise InputError(f"p: shape {p.shape}, expected ({self.qp.n_parameters},)")
        t0 = time.perf_counter()
        v, raw, status, iters = self._solve(p, warm)
        seconds = time.perf_counter() - t0
        self.solves += 1
        if not status.ok or v is None or not np.all(np.isfinite(v)):
            raise SolverError(self.name, raw, _HINT)
        return QPSolution(v, self.qp.objective(v, p), status, raw, iters, self.name, seconds)


# -- CVXPY ----------------------------------------------------------------------------------------


class CvxpyBackend(QPBackend):
    """CVXPY with a ``Parameter`` for ``p`` (DPP: compiled once), solved by Clarabel or OSQP."""

    def __init__(self, qp: ParametricQP, solver: str = "clarabel", **kw) -> None:
        self.name = solver
        self._solver = {"clarabel": "CLARABEL", "osqp": "OSQP"}[solver]
        super().__init__(qp, **kw)

    def _build(self) -> None:
        import cvxpy as cp

        qp = self.qp
        self._v = cp.Variable(qp.n_variables, name="v")
        self._p = cp.Parameter(qp.n_parameters, name="p", value=np.zeros(qp.n_parameters))
        v, p = self._v, self._p
        H = sp.csc_matrix(qp.H)
        cost = 0.5 * cp.quad_form(v, cp.psd_wrap(H)) + (qp.q0 + qp.Qp @ p) @ v
        cons = [qp.A_in @ v >= qp.l0 + qp.Lp @ p, qp.A_in @ v <= qp.u0 + qp.Up @ p]
        if qp.A_eq is not None:
            cons.append(qp.A_eq @ v == qp.b0 + qp.Bp @ p)
        self._problem = cp.Problem(cp.Minimize(cost), cons)
        if not self._problem.is_dpp():  # pragma: no cover - guarded by construction
            raise InputError("QP is not DPP: the parameter enters non-affinely")
        if self._solver == "OSQP":
            tol = max(self.tolerance, 1e-9)
            self._options = dict(eps_abs=tol, eps_rel=tol, max_iter=self.max_iterations, polishing=True)
        else:
            tol = self.tolerance
            self._options = dict(tol_gap_abs=tol, tol_gap_rel=tol, tol_feas=tol, max_iter=min(self.max_iterations, 200))
        # Compile once now (the first solve would do it anyway): build time is then measured apart.
        self._problem.get_problem_data(self._solver)

    def _solve(self, p, warm):
        import cvxpy as cp

        self._p.value = p
        if warm is not None:
            self._v.value = warm
        try:
            self._problem.solve(solver=self._solver, warm_start=True, **self._options)
        except cp.error.SolverError as exc:
            return None, f"solver_error: {exc}", SolveStatus.NUMERICAL_ERROR, 0
        raw = str(self._problem.status)
        stats = self._problem.solver_stats
        iters = int(stats.num_iters) if stats is not None and stats.num_iters is not None else 0
        v = None if self._v.value is None else np.asarray(self._v.value, dtype=float)
        return v, raw, status_from(self.name, raw), iters


# -- CasADi ---------------------------------------------------------------------------------------


def _casadi_sparse(A: sp.spmatrix):
    import casadi as ca

    A = sp.csc_matrix(A)
    A.sort_indices()
    sparsity = ca.Sparsity(A.shape[0], A.shape[1], A.indptr.tolist(), A.indices.tolist())
    return ca.DM(sparsity, A.data.tolist())


@contextlib.contextmanager
def _quiet_stdout():
    """Silence C-level stdout: qpOASES prints its licence banner on construction, whatever its
    print level, which would corrupt ``--json`` output on stdout."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, ValueError, OSError):  # pragma: no cover - captured streams without an fd
        yield
        return
    sys.stdout.flush()
    saved = os.dup(fd)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), fd)
            yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)


class _CasadiBase(QPBackend):
    """Common part: one stacked constraint matrix ``[A_eq; A_in]`` with per-row bounds."""

    def _stack(self):
        qp = self.qp
        blocks = [qp.A_eq, qp.A_in] if qp.A_eq is not None else [qp.A_in]
        return sp.vstack(blocks).tocsc()

    def _bounds(self, p):
        qp = self.qp
        if qp.A_eq is None:
            return qp.lower(p), qp.upper(p)
        b = qp.b(p)
        return np.concatenate([b, qp.lower(p)]), np.concatenate([b, qp.upper(p)])


class CasadiQPBackend(_CasadiBase):
    """CasADi ``conic`` with a QP plugin (``qpoases`` by default; ``osqp``, ``daqp``, ``proxqp``, ...)."""

    name = "casadi-qp"

    def __init__(self, qp: ParametricQP, plugin: str = "qpoases", **kw) -> None:
        self.plugin = plugin
        super().__init__(qp, **kw)

    def _build(self) -> None:
        import casadi as ca

        self._H = _casadi_sparse(sp.triu(self.qp.H) + sp.triu(self.qp.H, 1).T)
        self._A = _casadi_sparse(self._stack())
        opts: dict = {"error_on_fail": False, "print_time": False}
        if self.plugin == "qpoases":
            opts.update(printLevel="none", nWSR=self.max_iterations, sparse=False, schur=False)
        elif self.plugin == "osqp":
            tol = max(self.tolerance, 1e-9)
            opts["osqp"] = {"verbose": False, "eps_abs": tol, "eps_rel": tol, "max_iter": self.max_iterations}
            opts["warm_start_primal"] = True
        elif self.plugin == "daqp":
            pass
        with _quiet_stdout():
            self._conic = ca.conic("wingopt_qp", self.plugin, {"h": self._H.sparsity(), "a": self._A.sparsity()}, opts)

    def _solve(self, p, warm):
        lo, hi = self._bounds(p)
        args = dict(h=self._H, g=self.qp.q(p), a=self._A, lba=lo, uba=hi)
        if warm is not None:
            args["x0"] = warm
        out = self._conic(**args)
        stats = self._conic.stats()
        raw = str(stats.get("return_status", stats.get("success")))
        status = SolveStatus.OPTIMAL if stats.get("success", False) else status_from(self.name, raw)
        if status is SolveStatus.OPTIMAL and not stats.get("success", True):  # pragma: no cover - defensive
            status = SolveStatus.UNKNOWN
        iters = int(stats.get("iter_count", stats.get("n_iter", 0)) or 0)
        return np.asarray(out["x"], dtype=float).ravel(), f"{self.plugin}: {raw}", status, iters


class IpoptBackend(_CasadiBase):
    """CasADi ``nlpsol`` with IPOPT on the QP (constant Hessian and Jacobian declared to IPOPT)."""

    name = "ipopt"

    def _build(self) -> None:
        import casadi as ca

        qp = self.qp
        n = qp.n_variables
        x = ca.MX.sym("v", n)
        g = ca.MX.sym("q", n)  # the linear term is the NLP's parameter: p enters only through it
        H = _casadi_sparse(qp.H)
        A = _casadi_sparse(self._stack())
        nlp = {"x": x, "p": g, "f": 0.5 * ca.dot(x, ca.mtimes(H, x)) + ca.dot(g, x), "g": ca.mtimes(A, x)}
        tol = max(self.tolerance, 1e-12)
        opts = {
            "print_time": False,
            "error_on_fail": False,
            "ipopt": {
                "print_level": 0,
                "sb": "yes",
                "tol": tol,
                "max_iter": min(self.max_iterations, 3000),
                "hessian_constant": "yes",
                "jac_c_constant": "yes",
                "jac_d_constant": "yes",
                "mu_strategy": "adaptive",
            },
        }
        self._nlp = ca.nlpsol("wingopt_qp_ipopt", "ipopt", nlp, opts)

    def _solve(self, p, warm):
        lo, hi = self._bounds(p)
        args = dict(p=self.qp.q(p), lbg=lo, ubg=hi)
        if warm is not None:
            args["x0"] = warm
        out = self._nlp(**args)
        stats = self._nlp.stats()
        raw = str(stats.get("return_status", "unknown"))
        iters = int(stats.get("iter_count", 0))
        return np.asarray(out["x"], dtype=float).ravel(), raw, status_from(self.name, raw), iters


def make_backend(
    name: str, qp: ParametricQP, *, tolerance: float | None = None, plugin: str | None = None
) -> QPBackend:
    """Build the backend ``name`` (one of :data:`BACKENDS`) for ``qp``.

    ``tolerance`` defaults to 1e-8 (interior point) or 1e-7 (OSQP, polished); ``plugin`` picks the
    CasADi QP plugin for ``casadi-qp`` (default ``qpoases``).
    """
    name = str(name).lower()
    if name in ("clarabel", "osqp"):
        tol = tolerance if tolerance is not None else (1e-8 if name == "clarabel" else 1e-7)
        return CvxpyBackend(qp, solver=name, tolerance=tol)
    if name == "casadi-qp":
        return CasadiQPBackend(qp, plugin=plugin or "qpoases", tolerance=tolerance or 1e-8)
    if name == "ipopt":
        return IpoptBackend(qp, tolerance=tolerance or 1e-10)
    raise InputError(f"solver = {name!r}: expected one of {', '.join(BACKENDS)}")
