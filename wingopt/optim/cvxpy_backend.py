"""CVXPY backends: the parametric QP with a ``Parameter`` (DPP, compiled once), Clarabel or OSQP.

A re-solve only maps ``p`` to the solver data: CVXPY caches the canonicalisation; OSQP keeps its
factorisation and is warm-started. Clarabel is the robust interior-point fallback of the package
(always installed); OSQP is first-order (ADMM, polished).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from wingopt.errors import InputError
from wingopt.optim.qp import ParametricQP, QPBackend
from wingopt.optim.status import SolveStatus, status_from

__all__ = ["CvxpyBackend", "ClarabelBackend", "OsqpBackend", "cvxpy_options"]

_SOLVER = {"clarabel": "CLARABEL", "osqp": "OSQP"}


def cvxpy_options(solver: str, tolerance: float, max_iterations: int) -> dict:
    """Solver options for ``problem.solve`` (one place for the tolerances of both CVXPY solvers)."""
    if solver == "osqp":
        tol = max(tolerance, 1e-9)
        return dict(eps_abs=tol, eps_rel=tol, max_iter=max_iterations, polishing=True)
    return dict(tol_gap_abs=tolerance, tol_gap_rel=tolerance, tol_feas=tolerance, max_iter=min(max_iterations, 200))


class CvxpyBackend(QPBackend):
    """CVXPY with a ``Parameter`` for ``p`` (DPP: compiled once), solved by Clarabel or OSQP."""

    solver = "clarabel"

    def __init__(self, qp: ParametricQP, solver: str | None = None, **kw) -> None:
        if solver is not None:
            self.solver = solver
        self.name = self.solver
        self._solver = _SOLVER[self.solver]
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
        self._options = cvxpy_options(self.solver, self.tolerance, self.max_iterations)
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


class ClarabelBackend(CvxpyBackend):
    """Clarabel (interior point) behind CVXPY: the fallback that is always installed."""

    solver = "clarabel"
    default_tolerance = 1e-8


class OsqpBackend(CvxpyBackend):
    """OSQP (ADMM, polished) behind CVXPY."""

    solver = "osqp"
    default_tolerance = 1e-7
