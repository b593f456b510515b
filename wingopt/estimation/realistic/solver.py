"""Levenberg–Marquardt on a :class:`~wingopt.estimation.realistic.record_problem.RecordProblem`.

Nielsen's damping update on the dense normal equations ``(J^T J + mu diag) d = -J^T r`` (data
and prior rows together), the exact Jacobian at every accepted point. It stops when the model
predicts less than ``tol`` chi-square units of decrease, after ``max_iter`` iterations, when the
record's :class:`Budget` is spent, or when a ``monitor`` shown every iterate (:class:`Iterate`)
gives a reason to stop (:mod:`.stopping`). The Gauss–Newton matrix at the optimum is the
posterior precision (the cost is a chi-square).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wingopt.errors import SolverError

__all__ = ["Fit", "Budget", "Iterate", "Monitor", "levenberg_marquardt", "cost"]

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


Monitor = Callable[[Iterate], "str | None"]
"""Called once per iterate that has not converged; a string stops the fit and is its reason."""


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


def levenberg_marquardt(
    problem,
    theta0: np.ndarray,
    max_iter: int = 40,
    tol: float = 1e-2,
    budget: Budget | None = None,
    monitor: Monitor | None = None,
) -> Fit:
    """Minimise ``problem``'s chi-square from ``theta0``.

    Converged when the undamped Gauss–Newton step would lower the chi-square by less than ``tol``
    (its Newton decrement ``g^T H^-1 g``: the point is within ``sqrt(tol)`` posterior standard
    deviations of the minimum of the local model in every direction). The damped step's own
    predicted decrease is no test: with a large damping it is small far from the minimum. A spent
    ``budget`` stops it before the next iteration (``out_of_budget``; not converged), and so does a
    ``monitor`` that returns a reason for an iterate (``Fit.stopped``).
    """
    theta = np.array(theta0, dtype=float)
    mu, nu = 1e-3, 2.0
    rd, rp, Jd, Rp = problem.residuals(theta, jacobian=True)
    f = float(rd @ rd + rp @ rp)
    converged = False
    it = 0
    jacobian_first = True
    first_decrement = None
    stopped = None
    while True:
        H = Jd.T @ Jd + Rp.T @ Rp
        g = Jd.T @ rd + Rp.T @ rp
        try:
            decrement = float(g @ np.linalg.solve(H, g))
        except np.linalg.LinAlgError:
            decrement = np.inf
        first_decrement = decrement if first_decrement is None else first_decrement
        if decrement < tol:
            converged = True
            break
        if it >= max_iter or (budget is not None and budget.exhausted):
            break
        if monitor is not None:
            stopped = monitor(Iterate(it, theta, f, decrement, H, g))
            if stopped is not None:
                log.debug("LM: stopped by its monitor after %d iterations: %s", it, stopped)
                break
        it += 1
        if budget is not None:
            budget.used += 1
        dH = np.diag(H).copy()
        accepted = None
        while True:
            try:
                step = -np.linalg.solve(H + mu * np.diag(dH), g)
            except np.linalg.LinAlgError:
                mu *= 10.0
                continue
            pred = -(2 * g @ step + step @ H @ step)
            if not np.isfinite(pred):
                raise SolverError(
                    "realistic estimator",
                    "non-finite Levenberg–Marquardt step",
                    "check the data and the noise level, or use --model linear",
                )
            # after an accepted step the next trial is likely accepted too: its Jacobian comes with
            # its residuals (one tangent run instead of a trajectory and then a tangent)
            with np.errstate(over="ignore", invalid="ignore"):  # a diverging trial: a non-finite cost, rejected
                trial = problem.residuals(theta + step, jacobian=jacobian_first)
                rd1, rp1 = trial[0], trial[1]
                f1 = float(rd1 @ rd1 + rp1 @ rp1)
            rho = (f - f1) / pred if np.isfinite(f1) and pred > 0 else -1.0
            if rho > 0:
                log.debug(
                    "LM %d: cost %.6g -> %.6g (predicted %.3g, mu %.2g, decrement %.3g)", it, f, f1, pred, mu, decrement
                )
                theta = theta + step
                mu *= max(0.1, 1 - (2 * rho - 1) ** 3)
                nu = 2.0
                accepted = trial
                break
            jacobian_first = False
            mu *= nu
            nu *= 2.0
            if mu > 1e12:
                break
        if mu > 1e12:
            log.debug("LM: no decrease along any damped step (decrement %.3g): stopped", decrement)
            converged = decrement < 100 * tol  # rounding-limited near a minimum
            break
        rd, rp, Jd, Rp = accepted if len(accepted) == 4 else problem.residuals(theta, jacobian=True)
        jacobian_first = True
        f = float(rd @ rd + rp @ rp)
    log.debug("LM: %d iterations, cost %.4g, converged %s", it, f, converged)
    H = Jd.T @ Jd + Rp.T @ Rp
    out = not converged and it < max_iter and budget is not None and budget.exhausted
    return Fit(theta, float(rd @ rd), float(rp @ rp), H, Jd, rd, it, converged, out, first_decrement, stopped)
