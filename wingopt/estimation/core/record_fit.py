"""The record fits' adapter to the core least-squares solver, and what the fits share of it.

A :class:`~wingopt.estimation.core.record_problem.RecordProblem` (or any problem with
``residuals(theta, jacobian=)``) is minimised by :func:`fit_record` (``levenberg_marquardt``, the
name the fits call): the core solver (:mod:`wingopt.estimation.core.least_squares`) with Nielsen's
damping on the dense normal equations ``(J^T J + mu diag) d = -J^T r`` (data and prior rows
together) and the exact Jacobian at every accepted point. It stops when the undamped Gauss–Newton
step would remove less than ``tol`` chi-square units (the Newton decrement), after ``max_iter``
iterations, when the record's :class:`Budget` is spent, or when a ``monitor`` shown every iterate
(:class:`Iterate`) gives a reason to stop (:mod:`.stopping`: a reason in words stops it not
converged; a :class:`~.least_squares.Stop` is taken as it says, a caller's own convergence test).
The Gauss–Newton matrix at the optimum is the posterior precision (the cost is a chi-square)."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wingopt.errors import SolverError
from wingopt.estimation.core.least_squares import Damping, SolverState, Stop, StoppingPolicy, least_squares_fit

__all__ = ["Fit", "Budget", "Iterate", "Monitor", "fit_record", "levenberg_marquardt", "cost"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class Fit:
    """A converged fit: unknowns, cost parts, precision, data Jacobian, iterations."""

    theta: np.ndarray
    data_cost: float
    prior_cost: float
    precision: np.ndarray
    data_jacobian: np.ndarray
    residuals: np.ndarray
    iterations: int
    converged: bool
    out_of_budget: bool = False
    decrement: float = float("nan")
    """The Newton decrement ``g^T H^-1 g`` at ``theta0`` (chi-square units: the undamped Gauss–Newton
    step's predicted decrease from the start)."""
    stopped: str | None = None
    """The monitor's reason when it stopped the fit (not converged), else ``None``."""
    arrived: str | None = None
    """The monitor's reason when it called the fit converged (its own test), else ``None``."""

    @property
    def cost(self) -> float:
        return self.data_cost + self.prior_cost

    @property
    def covariance(self) -> np.ndarray:
        """Inverse of the precision (symmetrised; scaled unknowns)."""
        C = np.linalg.inv(self.precision)
        return 0.5 * (C + C.T)

    @property
    def effective_parameters(self) -> float:
        """``trace(J_d P^-1 J_d^T)``: the unknowns the data determine (the rest is prior)."""
        return float(np.einsum("ij,ji->", self.covariance, self.data_jacobian.T @ self.data_jacobian))


@dataclass(frozen=True, eq=False)
class Iterate:
    """An iterate of :func:`levenberg_marquardt` as its monitor sees it: ``index`` (0 the start),
    ``theta``, the chi-square ``cost``, the Newton ``decrement`` ``g^T H^-1 g`` (what one undamped
    Gauss–Newton step would remove), the Gauss–Newton matrix ``precision`` and the cost's half
    ``gradient`` ``g`` (the undamped step is ``-H^-1 g``)."""

    index: int
    theta: np.ndarray
    cost: float
    decrement: float
    precision: np.ndarray
    gradient: np.ndarray | None = None

    @property
    def log_evidence(self) -> float:
        """Laplace log-evidence here (up to the data's normalisation)."""
        return float(-0.5 * self.cost - 0.5 * np.linalg.slogdet(self.precision)[1])


Monitor = Callable[[Iterate], "str | Stop | None"]
"""Called once per iterate that has not converged; a string stops the fit (not converged) and is its
reason, a :class:`~.least_squares.Stop` stops it as it says (``converged`` or not)."""


def cost(problem, theta) -> tuple[float, float]:
    """Data and prior parts of the chi-square at ``theta``."""
    rd, rp = problem.residuals(theta)
    return float(rd @ rd), float(rp @ rp)


class Budget:
    """The work one record may cost, shared by all its fits: ``iterations`` Levenberg–Marquardt
    iterations in all (deterministic: the same record stops at the same point on any machine) and,
    optionally, ``seconds`` of CPU."""

    def __init__(self, iterations: int | None = None, seconds: float | None = None) -> None:
        self.iterations, self.seconds = iterations, seconds
        self.used = 0
        self.start = time.process_time()

    @property
    def spent(self) -> float:
        return time.process_time() - self.start

    @property
    def exhausted(self) -> bool:
        over_iterations = self.iterations is not None and self.used >= self.iterations
        return over_iterations or (self.seconds is not None and self.spent >= self.seconds)


@dataclass(frozen=True, eq=False)
class _Point:
    """The record's residuals at a point (with their Jacobians when computed) and its chi-square."""

    residuals: tuple
    cost: float


@dataclass(frozen=True, eq=False)
class _Local:
    """The record's Gauss–Newton model at a point: matrix ``H``, half gradient ``g``, residuals."""

    rd: np.ndarray
    rp: np.ndarray
    Jd: np.ndarray
    Rp: np.ndarray
    cost: float
    H: np.ndarray
    g: np.ndarray


class _RecordAdapter:
    """A record problem (``residuals(theta, jacobian=)``) as the core solver's problem: dense
    normal equations ``(J^T J + mu diag) d = -J^T r`` of data and prior rows together."""

    def __init__(self, problem) -> None:
        self.problem = problem

    def linearize(self, theta: np.ndarray, trial: _Point | None) -> _Local:
        # after an accepted step its Jacobian came with its residuals (one tangent run instead of a
        # trajectory and then a tangent)
        res = trial.residuals if trial is not None and len(trial.residuals) == 4 else None
        rd, rp, Jd, Rp = res if res is not None else self.problem.residuals(theta, jacobian=True)
        return _Local(rd, rp, Jd, Rp, float(rd @ rd + rp @ rp), Jd.T @ Jd + Rp.T @ Rp, Jd.T @ rd + Rp.T @ rp)

    def damped_step(self, local: _Local, mu: float) -> np.ndarray | None:
        try:
            return -np.linalg.solve(local.H + mu * np.diag(np.diag(local.H)), local.g)
        except np.linalg.LinAlgError:
            return None

    def predicted_decrease(self, local: _Local, step: np.ndarray) -> float:
        pred = -(2 * local.g @ step + step @ local.H @ step)
        if not np.isfinite(pred):
            raise SolverError(
                "realistic estimator",
                "non-finite Levenberg–Marquardt step",
                "check the data and the noise level, or use --model linear",
            )
        return pred

    def trial(self, theta: np.ndarray, step: np.ndarray, first: bool) -> _Point:
        # the first trial of an iteration is likely accepted: its Jacobian comes with its residuals
        with np.errstate(over="ignore", invalid="ignore"):  # a diverging trial: a non-finite cost, rejected
            res = self.problem.residuals(theta + step, jacobian=first)
            rd1, rp1 = res[0], res[1]
            return _Point(res, float(rd1 @ rd1 + rp1 @ rp1))


class _RecordStopping(StoppingPolicy):
    """The record fits' stopping rule: the Newton decrement below ``tol`` (converged), ``max_iter``
    iterations, a spent :class:`Budget`, or a reason from the ``monitor``."""

    def __init__(self, max_iter: int, tol: float, budget: Budget | None, monitor: Monitor | None) -> None:
        self.max_iter, self.tol, self.budget, self.monitor = max_iter, tol, budget, monitor
        self.first_decrement: float | None = None
        self.decrement = float("nan")
        self.stopped: str | None = None
        self.arrived: str | None = None

    def before_iteration(self, state: SolverState) -> Stop | None:
        local = state.local
        try:
            decrement = float(local.g @ np.linalg.solve(local.H, local.g))
        except np.linalg.LinAlgError:
            decrement = np.inf
        self.decrement = decrement
        self.first_decrement = decrement if self.first_decrement is None else self.first_decrement
        if decrement < self.tol:
            return Stop(True, "converged")
        if state.iterations >= self.max_iter:
            return Stop(False, "maximum iterations reached")
        if self.budget is not None and self.budget.exhausted:
            return Stop(False, "out of budget")
        if self.monitor is not None:
            verdict = self.monitor(Iterate(state.iterations, state.x, local.cost, decrement, local.H, local.g))
            if verdict is not None:
                stop = verdict if isinstance(verdict, Stop) else Stop(False, verdict)
                if stop.converged:
                    self.arrived = stop.reason
                else:
                    self.stopped = stop.reason
                log.debug("LM: stopped by its monitor after %d iterations: %s", state.iterations, stop.reason)
                return stop
        if self.budget is not None:
            self.budget.used += 1
        return None

    def stalled(self, state: SolverState) -> Stop:
        log.debug("LM: no decrease along any damped step (decrement %.3g): stopped", self.decrement)
        # converged if rounding-limited near a minimum
        return Stop(self.decrement < 100 * self.tol, "no decrease along any damped step")


_DAMPING = Damping(initial=1e-3, floor=0.1, singular=10.0)


def fit_record(
    problem,
    theta0: np.ndarray,
    max_iter: int = 40,
    tol: float = 1e-2,
    budget: Budget | None = None,
    monitor: Monitor | None = None,
) -> Fit:
    """Minimise ``problem``'s chi-square from ``theta0`` with the core solver
    (:class:`~wingopt.estimation.core.least_squares.LevenbergMarquardt`).

    Converged when the undamped Gauss–Newton step would lower the chi-square by less than ``tol``
    (its Newton decrement ``g^T H^-1 g``: the point is within ``sqrt(tol)`` posterior standard
    deviations of the minimum of the local model in every direction). The damped step's own
    predicted decrease is no test: with a large damping it is small far from the minimum. A spent
    ``budget`` stops it before the next iteration (``out_of_budget``; not converged), and so does a
    ``monitor`` that returns a reason for an iterate (``Fit.stopped``); a monitor's converged
    :class:`~.least_squares.Stop` ends it converged (``Fit.arrived``).
    """
    policy = _RecordStopping(max_iter, tol, budget, monitor)
    st = least_squares_fit(_RecordAdapter(problem), np.array(theta0, dtype=float), policy, _DAMPING)
    it, converged, local = st.iterations, st.stop.converged, st.local
    log.debug("LM: %d iterations, cost %.4g, converged %s", it, local.cost, converged)
    out = not converged and it < max_iter and budget is not None and budget.exhausted
    rd = local.rd
    data, prior = float(rd @ rd), float(local.rp @ local.rp)
    decrement = policy.first_decrement
    return Fit(st.x, data, prior, local.H, local.Jd, rd, it, converged, out, decrement, policy.stopped, policy.arrived)


levenberg_marquardt = fit_record
"""The name the record fits call (:func:`fit_record`)."""
