"""The steady full-field fit: the frames' mean deflection, the load it implies, the prestrains' part.

The mean field ``W̄`` (every frame fitted, missing points filled by the frame's fit, then averaged:
a buffeting record's mean is then the mean over the same frames at every point) and its standard
error ``tau = sigma_W / sqrt(frames)`` are fitted by the load shapes of each prior through
:class:`~.system.PressureFromShape`. The priors are weighed by their evidence.

The prestrains: a steady field does not identify them. For any ``e0`` the measured shape implies a
pressure ``F(w; e0)``, affine in the prestress; the in-plane displacements follow from ``w`` and
Poisson's ratio alone (the in-plane stiffness cancels in their equilibrium and a uniform prestrain
does not enter it). Only the load prior's smoothness can prefer one ``e0``: ``prestrain="prior"``
(default) keeps the prior's (the problem file's, or a calibration's) and carries its uncertainty
into the band (``dL/de0`` by central differences); ``prestrain="fit"`` adds the field's own pull and
reports the posterior (Laplace, numerical Hessian). Either way ``info`` reports that pull: the
log-evidence change over one prior std.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from wingopt.estimation.core.load_model import LoadShapes
from wingopt.estimation.core.record_problem import ParameterPrior
from wingopt.estimation.fullfield.system import Posterior, PressureFromShape, posterior

__all__ = ["PrestrainPrior", "SteadyFit", "fit_prior", "STEP"]

log = logging.getLogger(__name__)

STEP = 0.5
"""Central-difference step for ``dL/de0`` and the Hessian, in prior standard deviations."""

LIMIT = 4.0
"""``prestrain="fit"`` searches within this many prior standard deviations."""


@dataclass(frozen=True)
class PrestrainPrior:
    """The prestrains' Gaussian prior: mean ``(2,)`` and its Cholesky factor ``(2, 2)``; ``e0 = mean + L theta``."""

    mean: np.ndarray
    chol: np.ndarray
    calibrated: bool

    @classmethod
    def of(cls, prior: ParameterPrior, calibrated: bool) -> PrestrainPrior:
        sx, sy = prior.mean_std("prestrain_x")[1], prior.mean_std("prestrain_y")[1]
        r = prior.correlation if prior.prestrain_std is not None else 0.0
        cov = np.array([[sx * sx, r * sx * sy], [r * sx * sy, sy * sy]])
        return cls(np.array(prior.prestrain, float), np.linalg.cholesky(cov), calibrated)

    def at(self, theta) -> tuple[float, float]:
        e = self.mean + self.chol @ np.asarray(theta, float)
        return float(e[0]), float(e[1])

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.sum(self.chol**2, axis=1))


@dataclass(frozen=True, eq=False)
class SteadyFit:
    """One load prior's steady fit: the posterior at the chosen prestrains and the lift's parts."""

    label: str
    shapes: LoadShapes
    system: PressureFromShape
    prior: PrestrainPrior
    theta: np.ndarray
    theta_cov: np.ndarray
    post: Posterior
    lift: float
    lift_std_load: float
    lift_grad: np.ndarray
    pull: float

    @property
    def lift_std(self) -> float:
        """Lift std: the load's posterior and the prestrains' (prior or posterior)."""
        return float(np.sqrt(self.lift_std_load**2 + self.lift_grad @ self.theta_cov @ self.lift_grad))

    @property
    def log_evidence(self) -> float:
        return self.post.log_evidence

    @property
    def prestrain(self) -> tuple[float, float]:
        return self.prior.at(self.theta)

    @property
    def prestrain_std(self) -> np.ndarray:
        L = self.prior.chol
        return np.sqrt(np.diag(L @ self.theta_cov @ L.T))

    def load(self) -> np.ndarray:
        """Load coefficients in the load basis."""
        return self.shapes.coefficients(self.post.c)

    def deflection(self) -> np.ndarray:
        return self.system.deflection(self.prestrain, self.post.c)


def _solve(system: PressureFromShape, shapes: LoadShapes, y0: np.ndarray, weight, e0) -> Posterior:
    A, offset, *_ = system.at(e0)
    return posterior(A, y0 + offset, weight, shapes.prior_std)


def fit_prior(
    label: str,
    shapes: LoadShapes,
    system: PressureFromShape,
    y0: np.ndarray,
    weight: np.ndarray,
    prior: PrestrainPrior,
    mode: str,
    given: tuple[np.ndarray, np.ndarray] | None = None,
) -> SteadyFit:
    """Fit one load prior (``y0 = W̄ - B ẑ``; ``weight = 1/tau^2``) with the prestrains as ``mode`` says
    (``"prior"``, ``"fit"``), or at ``given = (theta, cov)`` (the frames' dynamics, :mod:`.tension`)."""

    def post_at(theta) -> Posterior:
        return _solve(system, shapes, y0, weight, prior.at(theta))

    def neg_log_post(theta) -> float:
        if min(prior.at(theta)) <= 0 or np.max(np.abs(theta)) > LIMIT:
            return np.inf  # outside the physical range, or far outside the prior
        return -post_at(theta).log_evidence + 0.5 * float(np.sum(np.asarray(theta) ** 2))

    theta, cov = (np.zeros(2), np.eye(2)) if given is None else given
    if mode == "fit" and given is None:
        simplex = np.array([[0.0, 0.0], [0.5, 0.0], [0.0, 0.5]])  # half a prior std: the default's is 1e-4
        opts = {"xatol": 1e-3, "fatol": 1e-3, "initial_simplex": simplex}
        res = minimize(neg_log_post, np.zeros(2), method="Nelder-Mead", options=opts)
        theta = res.x
        with np.errstate(invalid="ignore"):
            H = _hessian(neg_log_post, theta, STEP / 4)
        ok = np.all(np.isfinite(H)) and np.all(np.linalg.eigvalsh(H) > 0)
        cov = np.linalg.inv(H) if ok else np.eye(2)  # at the search's edge or on a saddle: the prior's
    post = post_at(theta)
    g = np.zeros(2)
    for i in range(2):
        d = np.zeros(2)
        d[i] = STEP
        g[i] = (shapes.lift_row @ post_at(theta + d).c - shapes.lift_row @ post_at(theta - d).c) / (2 * STEP)
    h = _hessian(lambda th: -post_at(th).log_evidence, np.zeros(2))
    pull = float(np.sqrt(max(np.linalg.eigvalsh(h).max(), 0.0)))
    lift = float(shapes.lift_row @ post.c)
    std_load = float(np.sqrt(post.variance(shapes.lift_row)))
    return SteadyFit(label, shapes, system, prior, theta, cov, post, lift, std_load, g, pull)


def _hessian(f, x: np.ndarray, h: float = STEP) -> np.ndarray:
    """Central-difference Hessian of ``f`` at ``x`` (2-D)."""
    n = x.size
    H = np.zeros((n, n))
    f0 = f(x)
    for i in range(n):
        ei = np.zeros(n)
        ei[i] = h
        H[i, i] = (f(x + ei) - 2 * f0 + f(x - ei)) / h**2
        for j in range(i + 1, n):
            ej = np.zeros(n)
            ej[j] = h
            H[i, j] = H[j, i] = (f(x + ei + ej) - f(x + ei - ej) - f(x - ei + ej) + f(x - ei - ej)) / (4 * h * h)
    return 0.5 * (H + H.T)
