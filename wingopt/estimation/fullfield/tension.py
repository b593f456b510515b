"""The tension from a buffeting record's frames: the membrane's dynamics, not the load prior.

A steady field implies a pressure for any prestrain. A *buffeting* record does not: the flow scales
its pressure, ``P(x, y, t) = a(t) P̄(x, y)``, and the membrane answers with its own stiffness and
inertia (``rho h`` is known). For prestrains ``e0`` every frame's balance (:mod:`.system`, inertia
and damping from the spectral time derivatives of :mod:`.frames`) gives ``y_k = A c_k``; with the
load's shape held to the steady one, ``c_k = a_k c̄(e0)``, only the amplitude ``a_k`` is free per
frame. The chi-square of these rank-one fits over all frames is a function of ``e0`` alone: a wrong
tension leaves a residual that no amplitude removes (the frames' shape changes with the load
through the stiffening and the inertia, differently for another tension).

Every term is affine in the prestress (``F = Tx Gx z + Ty Gy z + F_nl(z)``, the damping's stiffness
part likewise), so the frames' forces are formed once; an evaluation costs one tangent
factorisation and one multi-right-hand-side solve. Measured on buffeting FvK records (docs/dic.md):
the lift's combination of the prestrains is fixed to a fraction of a percent, the two prestrains
apart much less well (a valley, correlation ≈ -0.9, and a bias along it of about 10 %): only the
stiff direction is kept, the prior stays along the valley (:func:`_identified`). The fit is refused
(the prior kept) when the record fluctuates too little or the rank-one model does not explain the
frames.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from wingopt.estimation.core.load_model import LoadShapes
from wingopt.estimation.core.model_form import PRESTRAIN_MODEL_FORM_REL
from wingopt.estimation.fullfield.data import FieldData
from wingopt.estimation.fullfield.frames import _derivatives
from wingopt.estimation.fullfield.steady import STEP, PrestrainPrior, _hessian
from wingopt.estimation.fullfield.system import PressureFromShape, posterior
from wingopt.membrane.parameters import MembraneParameters

__all__ = ["DynamicTension", "dynamic_tension", "fluctuation", "MIN_FLUCTUATION", "MAX_CHI2", "MIN_FRAMES"]

log = logging.getLogger(__name__)

MIN_FLUCTUATION = 5.0
"""The frames' RMS deflection fluctuation must exceed this many times the point noise."""

MAX_CHI2 = 1.5
"""The rank-one fits must reach this chi-square per datum, or the result is not used."""

MIN_FRAMES = 32
"""Fewer frames carry no dynamics worth fitting."""


@dataclass(frozen=True)
class DynamicTension:
    """The frames' own prestrains: ``theta`` on the prior (``e0 = mean + L theta``), its covariance,
    the rank-one fits' chi-square per datum, the fluctuation-to-noise ratio and whether it is used."""

    theta: np.ndarray
    cov: np.ndarray
    chi2_per_datum: float
    fluctuation: float
    used: bool
    reason: str

    def as_dict(self, prior: PrestrainPrior) -> dict:
        e = prior.at(self.theta)
        L = prior.chol
        s = np.sqrt(np.diag(L @ self.cov @ L.T))
        return {
            "used": self.used,
            "reason": self.reason,
            "prestrain": list(e),
            "prestrain_std": s.tolist(),
            "chi2_per_datum": self.chi2_per_datum,
            "fluctuation_to_noise": self.fluctuation,
        }


class _Frames:
    """The frames' affine parts, formed once."""

    def __init__(self, data: FieldData, system: PressureFromShape) -> None:
        fr, fvk = data.frames, system.fvk
        self.idx = idx = np.flatnonzero(data.used)
        Z = data.fit.coef[idx]
        zd, zdd = _derivatives(fr.t[idx], Z)
        bare = fvk.with_params(MembraneParameters(0.0, 0.0, fvk.params.viscous_scale, fvk.params.kelvin_voigt_scale))
        mat, par = fvk.problem.material, fvk.params
        self.fixed = (  # F_nl(z) + rho h M z'' + s_v gamma M z'
            np.stack([bare.force(z) for z in Z], axis=1)
            + fvk.mass @ zdd.T
            + par.viscous_scale * mat.viscous * (fvk.gram @ zd.T)
        )
        kv = par.kelvin_voigt_scale * mat.kelvin_voigt
        self.gx = fvk.gx @ (Z.T + kv * zd.T)  # Tx (Gx z + s_kv eta Gx z')
        self.gy = fvk.gy @ (Z.T + kv * zd.T)
        self.valid = fr.valid[idx]
        self.y0 = np.where(self.valid, fr.w[idx], 0.0) - Z @ data.basis.T
        self.basis = data.basis


def fluctuation(data: FieldData) -> float:
    """The frames' RMS deflection fluctuation about their mean, in units of the point noise."""
    return float(np.sqrt(np.mean(((data.fit.coef[data.used] - data.mean_z) @ data.basis.T) ** 2))) / data.sigma


def dynamic_tension(
    data: FieldData,
    shapes: LoadShapes,
    system: PressureFromShape,
    y0: np.ndarray,
    weight: np.ndarray,
    prior: PrestrainPrior,
) -> DynamicTension:
    """The prestrains that make every frame's load the steady load's shape times an amplitude (module docstring)."""
    fluct = fluctuation(data)
    if data.count < MIN_FRAMES or fluct < MIN_FLUCTUATION:
        why = f"{data.count} frames, fluctuation {fluct:.3g} x the noise: too little dynamics to fit"
        return DynamicTension(np.zeros(2), np.eye(2), float("nan"), fluct, False, why)
    fr = _Frames(data, system)
    n_data = int(fr.valid.sum())
    w2 = 1.0 / data.sigma**2

    def chi2(theta) -> float:
        e0 = prior.at(theta)
        if min(e0) <= 0:
            return np.inf
        A, offset, solve, _, _, fvk = system.at(e0)
        c = posterior(A, y0 + offset, weight, shapes.prior_std).c
        tx, ty = fvk.prestress
        s = solve(fr.fixed + tx * fr.gx + ty * fr.gy)
        Y = np.where(fr.valid, fr.y0 + (fr.basis @ s).T, 0.0)
        g = A @ c
        G = np.where(fr.valid, g[None, :], 0.0)
        a = np.sum(G * Y, axis=1) / np.maximum(np.sum(G * G, axis=1), 1e-300)
        r = Y - a[:, None] * G
        return float(np.sum(r * r) * w2)

    def objective(theta) -> float:
        return 0.5 * chi2(theta) + 0.5 * float(np.sum(np.asarray(theta) ** 2))

    simplex = np.array([[0.0, 0.0], [0.5, 0.0], [0.0, 0.5]])  # half a prior std: the default's is 1e-4
    res = minimize(
        objective, np.zeros(2), method="Nelder-Mead", options={"xatol": 1e-3, "fatol": 0.05, "initial_simplex": simplex}
    )
    c2 = chi2(res.x) / max(n_data - 2 * data.count, 1)
    with np.errstate(invalid="ignore"):
        H = _hessian(objective, res.x, STEP / 8)
    ok = bool(np.all(np.isfinite(H)) and np.all(np.linalg.eigvalsh(H) > 0))
    theta, cov = _identified(res.x, H, c2, prior) if ok else (res.x, np.eye(2))
    if not ok or c2 > MAX_CHI2:
        why = f"the rank-one frames do not fit (chi-square per datum {c2:.3g})" if ok else "no minimum found"
        log.info("dynamic tension not used: %s", why)
        return DynamicTension(theta, cov, c2, fluct, False, why)
    return DynamicTension(theta, cov, c2, fluct, True, f"{data.count} frames, {res.nfev} evaluations")


def _identified(theta: np.ndarray, H: np.ndarray, c2: float, prior: PrestrainPrior) -> tuple[np.ndarray, np.ndarray]:
    """Keep what the frames identify: the stiff direction of the Hessian ``H`` (whitened by the prior),
    nearly the prestrains' common scale, with its Laplace variance (inflated by the misfit) and a
    model-form floor of ``PRESTRAIN_MODEL_FORM_REL`` of the prestrain (measured: the scale came out
    2-2.6 % off at a Laplace std of 0.2 %); along the soft one, their ratio, the prior, mean and
    spread (there the fit was 12-16 % off, many times its Laplace std)."""
    lam, V = np.linalg.eigh(H)
    v = V[:, 1]
    keep = float(v @ theta) * v
    floor = PRESTRAIN_MODEL_FORM_REL * float(np.linalg.norm(prior.mean)) / float(np.linalg.norm(prior.chol @ v))
    var = max(max(1.0, c2) / lam[1], floor**2)
    return keep, np.outer(v, v) * var + np.outer(V[:, 0], V[:, 0])
