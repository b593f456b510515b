"""The MHE's window solvers ``numpy`` and ``cvxpy`` (adapters to the core Levenberg–Marquardt
solver, :mod:`wingopt.estimation.core.least_squares`) and the window-solver interface.

* ``numpy``: Levenberg–Marquardt on the window's least-squares cost with dense Cholesky steps
  (Gauss–Newton matrix, or the exact Hessian when it is positive definite). No bounds. The
  fastest; the default.
* ``cvxpy``: the same Gauss–Newton/Levenberg–Marquardt iteration, each step a least-distance QP
  of :mod:`wingopt.optim.least_distance` (CVXPY with Parameters, Clarabel by default, OSQP, or
  DAQP); supports the pressure bounds.

Status mapping and failure path (:class:`~wingopt.errors.SolverError` naming backend, raw status
and hint) come from :mod:`wingopt.optim.status`. Every backend works in scaled unknowns
``xi = theta / scale`` so that all unknowns are O(1).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.core.least_squares import Damping, SolverState, Stop, StoppingPolicy, least_squares_fit
from wingopt.estimation.mhe.window import WindowProblem
from wingopt.optim.least_distance import LeastDistanceQP
from wingopt.optim.status import SolveStatus, fail, status_from

__all__ = ["WindowSolution", "WindowSolver", "NumpySolver", "CvxpySolver"]

log = logging.getLogger(__name__)


@dataclass(eq=False)
class WindowSolution:
    """Result of one window solve.

    Attributes
    ----------
    theta : ndarray
        Optimal unknowns (physical modal units).
    cost : float
        ``V(theta)`` (chi-square units).
    hessian : ndarray
        Gauss–Newton matrix ``J^T W J + H0`` at ``theta``: the posterior precision.
    status : SolveStatus
    raw_status : str
        The backend's own status.
    iterations : int
    backend : str
    seconds : float
    """

    theta: np.ndarray
    cost: float
    hessian: np.ndarray
    status: SolveStatus
    raw_status: str
    iterations: int
    backend: str
    seconds: float


class WindowSolver:
    """Interface: ``solve(problem, theta0) -> WindowSolution``."""

    name = "base"

    def __init__(self, max_iterations: int = 100, tolerance: float = 1e-3) -> None:
        self.max_iterations = int(max_iterations)
        self.tolerance = float(tolerance)

    def solve(self, problem: WindowProblem, theta0: np.ndarray) -> WindowSolution:  # pragma: no cover
        raise NotImplementedError

    def _finish(self, problem, theta, raw, iterations, t0, status=None) -> WindowSolution:
        status = status or status_from(self.name, raw)
        if not status.ok:
            raise fail(self.name, raw, "mhe", status)
        H, _ = problem.normal_equations(theta)
        return WindowSolution(
            theta, problem.cost(theta), H, status, raw, iterations, self.name, time.perf_counter() - t0
        )


def _cholesky(A: np.ndarray) -> np.ndarray | None:
    try:
        return np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        return None


def _chol_solve(L: np.ndarray, b: np.ndarray) -> np.ndarray:
    import scipy.linalg as sla

    return sla.cho_solve((L, True), b, check_finite=False)


@dataclass(frozen=True, eq=False)
class _Window:
    """A window's scaled Gauss–Newton (or Newton) model at ``xi``: ``cost``, matrix ``Hs``, ``bs``."""

    xi: np.ndarray
    cost: float
    Hs: np.ndarray
    bs: np.ndarray


@dataclass(frozen=True)
class _Trial:
    cost: float


class _WindowProblem:
    """A :class:`WindowProblem` in scaled unknowns ``xi = theta / scale`` as the core solver's
    problem; the damped step is the backend's (:meth:`_DampedWindowSolver._step`)."""

    def __init__(self, solver: _DampedWindowSolver, problem: WindowProblem) -> None:
        self.solver, self.problem = solver, problem

    def linearize(self, xi: np.ndarray, trial: _Trial | None) -> _Window:
        problem, D = self.problem, self.problem.scale
        if trial is None:
            cost = problem.cost(D * xi)
            if not np.isfinite(cost):
                raise fail(self.solver.name, "non-finite cost at the start", "mhe")
        else:
            cost = trial.cost
        H, b = problem.normal_equations(D * xi)
        Hs = D[:, None] * H * D[None, :]
        bs = D * b
        if self.solver.hessian == "newton":
            Hx = Hs + D[:, None] * problem.second_order(D * xi) * D[None, :]
            if _cholesky(Hx) is not None:
                Hs = 0.5 * (Hx + Hx.T)
        return _Window(xi, cost, Hs, bs)

    def damped_step(self, local: _Window, mu: float) -> np.ndarray | None:
        return self.solver._step(self.problem, local.xi, local.Hs, local.bs, mu)

    def predicted_decrease(self, local: _Window, d: np.ndarray) -> float:
        return 2.0 * local.bs @ d - d @ local.Hs @ d

    def trial(self, xi: np.ndarray, d: np.ndarray, first: bool) -> _Trial:
        return _Trial(self.problem.cost(self.problem.scale * (xi + d)))


class _WindowStopping(StoppingPolicy):
    """The windows' stopping rule, ``tolerance`` in chi-square units: converged once an accepted
    step was predicted and found to lower the cost by less than that (a change far below the
    cost's statistical spread ``sqrt(2 n)``), or when no damping lowers it and the model predicts
    little; stalled otherwise; ``max_iterations`` at most."""

    def __init__(self, max_iterations: int, tolerance: float) -> None:
        self.max_iterations, self.tolerance = max_iterations, tolerance

    def before_iteration(self, state: SolverState) -> Stop | None:
        return None if state.iterations < self.max_iterations else Stop(False, "maximum iterations reached")

    def after_step(self, state: SolverState) -> Stop | None:
        if state.predicted <= self.tolerance and state.decrease <= 10 * self.tolerance:
            return Stop(True, "converged")
        return None

    def hopeless(self, state: SolverState) -> bool:
        return state.predicted <= self.tolerance

    def stalled(self, state: SolverState) -> Stop:
        if state.predicted <= 10 * self.tolerance:
            return Stop(True, "converged (no further decrease)")
        return Stop(False, "stalled")


# Start as Gauss–Newton: warm-started windows are next to their optimum; a failed step raises the
# damping quickly (x2, x4, ...).
_DAMPING = Damping(initial=1e-8, floor=1.0 / 3.0)


class _DampedWindowSolver(WindowSolver):
    """The numpy and CVXPY backends: the core Levenberg–Marquardt solver
    (:mod:`wingopt.estimation.core.least_squares`) in scaled unknowns with Nielsen's damping.

    Subclasses provide :meth:`_step`, the minimiser of the damped quadratic model.
    ``tolerance`` is in chi-square units: the iteration stops once the model predicts less
    decrease than that (a change of the cost far below its statistical spread ``sqrt(2 n)``).
    """

    hessian = "gauss-newton"

    def _step(self, problem, xi, Hs, bs, mu) -> np.ndarray | None:  # pragma: no cover
        raise NotImplementedError

    def solve(self, problem: WindowProblem, theta0: np.ndarray) -> WindowSolution:
        t0 = time.perf_counter()
        D = problem.scale
        policy = _WindowStopping(self.max_iterations, self.tolerance)
        st = least_squares_fit(_WindowProblem(self, problem), np.asarray(theta0, dtype=float) / D, policy, _DAMPING)
        raw = st.stop.reason
        status = SolveStatus.OPTIMAL if st.stop.converged else None
        if raw == "maximum iterations reached":
            # The cost is flat along poorly observed directions; an answer after the limit is
            # still a usable (inaccurate) estimate.
            status = SolveStatus.OPTIMAL_INACCURATE
        if raw == "stalled":
            status = SolveStatus.NUMERICAL_ERROR
        return self._finish(problem, D * st.x, raw, st.iterations, t0, status)


class NumpySolver(_DampedWindowSolver):
    """Dense Levenberg–Marquardt; ``hessian="newton"`` uses the exact Hessian where it is positive definite."""

    name = "numpy"

    def __init__(self, max_iterations: int = 100, tolerance: float = 1e-3, hessian: str = "newton") -> None:
        super().__init__(max_iterations, tolerance)
        if hessian not in ("gauss-newton", "newton"):
            raise InputError(f"hessian = {hessian!r}: expected 'gauss-newton' or 'newton'")
        self.hessian = hessian

    def solve(self, problem: WindowProblem, theta0: np.ndarray) -> WindowSolution:
        if problem.bounds is not None:
            raise InputError("pressure bounds need the cvxpy or ipopt MHE backend, not numpy")
        return super().solve(problem, theta0)

    def _step(self, problem, xi, Hs, bs, mu):
        L = _cholesky(Hs + mu * np.diag(np.maximum(np.diag(Hs), 1e-12)))
        return None if L is None else _chol_solve(L, bs)


class CvxpySolver(_DampedWindowSolver):
    """Gauss–Newton/LM steps as convex QPs, built once per window shape with CVXPY Parameters.

    The LM subproblem ``min d^T H d - 2 b^T d`` s.t. ``lo <= A (xi + d) <= hi`` is passed in whitened
    form: with ``H = L L^T`` and ``z = L^T d`` it reads ``min ||z - L^-1 b||^2`` s.t.
    ``lo - A xi <= (A L^-T) z <= hi - A xi``. It is the same QP, but its objective is perfectly
    conditioned, which the interior-point and ADMM solvers need: the arrival cost makes ``H`` span
    ten or more decades.
    """

    name = "cvxpy"

    def __init__(self, max_iterations: int = 100, tolerance: float = 1e-3, solver: str = "clarabel") -> None:
        super().__init__(max_iterations, tolerance)
        self.qp_solver = str(solver).lower()
        self._qp = LeastDistanceQP(self.qp_solver, label=f"cvxpy-{self.qp_solver}", context="mhe")

    @property
    def label(self) -> str:
        return f"cvxpy-{self.qp_solver}"

    def _step(self, problem, xi, Hs, bs, mu):
        import scipy.linalg as sla

        Hd = Hs + mu * np.diag(np.maximum(np.diag(Hs), 1e-12))
        L = _cholesky(Hd)
        if L is None:
            return None
        c = sla.solve_triangular(L, bs, lower=True)
        M = lo = hi = None
        if problem.bounds is not None and problem.bounds.A.shape[0]:
            D = problem.scale
            As = problem.bounds.A * D[None, :]
            M = sla.solve_triangular(L, As.T, lower=True).T  # (A L^-T) = (L^-1 A^T)^T
            Ax = As @ xi
            lim = 1e30
            lo = np.maximum(problem.bounds.lo, -lim) - Ax
            hi = np.minimum(problem.bounds.hi, lim) - Ax
        return sla.solve_triangular(L.T, self._qp.solve(c, M, lo, hi), lower=False)

    def solve(self, problem: WindowProblem, theta0: np.ndarray) -> WindowSolution:
        sol = super().solve(problem, theta0)
        sol.backend = self.label
        return sol
