"""Least-distance QPs ``min ||z - c||^2  s.t.  lo <= M z <= hi`` (the MHE's Gauss–Newton steps).

The moving-horizon estimator whitens each Levenberg–Marquardt step (``H = L L^T``, ``z = L^T d``)
so that its QP has the identity as Hessian and only ``c``, ``M`` and the bounds change between
steps. Solved by CVXPY (one problem per shape with ``Parameter`` data, Clarabel or OSQP) or by
DAQP, which is itself a least-distance solver. Status and failure path: :mod:`wingopt.optim.status`.
"""

from __future__ import annotations

import numpy as np

from wingopt.optim.cvxpy_backend import _SOLVER
from wingopt.optim.daqp_backend import DAQP_EXITFLAGS
from wingopt.optim.registry import check_solver, solver_names
from wingopt.optim.status import fail, status_from

__all__ = ["LeastDistanceQP", "LDP_SOLVERS"]

LDP_SOLVERS = solver_names("least-distance")
"""QP solvers of the least-distance steps: the ``least-distance`` names of the registry."""


class LeastDistanceQP:
    """Re-solvable least-distance QP; one compiled problem per ``(n, rows)`` shape.

    Parameters
    ----------
    solver : str
        One of :data:`LDP_SOLVERS`.
    label : str, optional
        The backend name a failure reports (default ``solver``).
    context : str
        Hint context of a failure (:data:`wingopt.optim.status.CONTEXT_HINTS`).
    """

    def __init__(self, solver: str = "clarabel", label: str | None = None, context: str = "mhe") -> None:
        self.solver = check_solver(solver, "least-distance", "qp_solver")
        self.label = label or self.solver
        self.context = context
        self._cache: dict = {}

    def solve(self, c: np.ndarray, M: np.ndarray | None = None, lo=None, hi=None) -> np.ndarray:
        """The minimiser ``z``; raises :class:`~wingopt.errors.SolverError` when the solver fails."""
        c = np.asarray(c, dtype=float)
        if M is None or M.shape[0] == 0:
            return c.copy()  # no constraint: the minimiser is c itself
        if self.solver == "daqp":
            return self._daqp(c, M, lo, hi)
        return self._cvxpy(c, M, lo, hi)

    def _daqp(self, c, M, lo, hi):
        import daqp

        n = c.size
        M = np.ascontiguousarray(M, dtype=float)
        x, _, flag, _ = daqp.solve(2.0 * np.eye(n), -2.0 * c, M, np.asarray(hi, float), np.asarray(lo, float))
        if flag != 1:
            raise fail(self.label, DAQP_EXITFLAGS.get(int(flag), f"exit flag {flag}"), self.context)
        return np.asarray(x, dtype=float)

    def _build(self, n: int, nb: int):
        import cvxpy as cp

        key = (n, nb)
        if key not in self._cache:
            z, c = cp.Variable(n), cp.Parameter(n)
            M, lo, hi = cp.Parameter((nb, n)), cp.Parameter(nb), cp.Parameter(nb)
            prob = cp.Problem(cp.Minimize(cp.sum_squares(z - c)), [M @ z >= lo, M @ z <= hi])
            self._cache[key] = (prob, z, c, M, lo, hi)
        return self._cache[key]

    def _cvxpy(self, c, M, lo, hi):
        import cvxpy as cp

        prob, z, pc, pM, plo, phi = self._build(c.size, M.shape[0])
        pc.value, pM.value, plo.value, phi.value = c, M, lo, hi
        try:
            if self.solver == "clarabel":
                prob.solve(solver=cp.CLARABEL)
            else:
                prob.solve(solver=_SOLVER["osqp"], eps_abs=1e-10, eps_rel=1e-10, max_iter=50000, polishing=True)
        except cp.SolverError as exc:
            raise fail(self.label, f"solver error: {exc}", self.context) from None
        if not status_from(self.solver, prob.status).ok or z.value is None:
            raise fail(self.label, str(prob.status), self.context)
        return np.asarray(z.value, dtype=float)
