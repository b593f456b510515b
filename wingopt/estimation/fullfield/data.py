"""The DIC frames as the full-field estimator uses them: frame fits, the mean field and its noise.

Every usable frame (at least ``min_valid`` of its points valid) is fitted in the estimator's
deflection space (:func:`~wingopt.membrane.dic_fit.fit_frames`, a light curvature penalty); the
noise ``sigma_W`` of one frame's points comes from the fits' residuals. The mean field is the
average over the used frames with a missing point taken from its frame's fit (so that every
point averages the same frames: on a buffeting record a point missing in some frames would
otherwise carry a different mean load), its standard error ``sigma_W / sqrt(frames)``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError
from wingopt.measurements.dic import DICFrames
from wingopt.membrane.dic_fit import FrameFit, fit_frames
from wingopt.membrane.model import MembraneModel

__all__ = ["FieldData", "field_data", "inplane_check"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class FieldData:
    """Frames fitted in the estimator's space.

    Attributes
    ----------
    frames : DICFrames
    used : ndarray of bool (F,)
        Frames with enough valid points (and a fit).
    fit : FrameFit
        The deflection fits (``fit.coef`` NaN for unused frames).
    mean_w : ndarray (P,)
        Mean deflection at the points over the used frames (missing points from their frame's fit).
    mean_z : ndarray (n,)
        Mean of the used frames' fits.
    sigma : float
        Noise std of one frame's ``W`` (m), from the fit residuals.
    """

    frames: DICFrames
    used: np.ndarray
    fit: FrameFit
    mean_w: np.ndarray
    mean_z: np.ndarray
    sigma: float

    @property
    def count(self) -> int:
        return int(self.used.sum())

    @property
    def tau(self) -> float:
        """Standard error of the mean field at a point (m)."""
        return self.sigma / np.sqrt(max(self.count, 1))

    @property
    def basis(self) -> np.ndarray:
        return self.fit.basis


def field_data(frames: DICFrames, model: MembraneModel, smoothing: float, min_valid: float) -> FieldData:
    """Fit every usable frame of ``frames`` in ``model``'s deflection space (module docstring)."""
    enough = frames.valid.mean(axis=1) >= min_valid
    if not enough.any():
        best = float(frames.valid.mean(axis=1).max()) if frames.n_frames else 0.0
        raise InputError(
            f"{frames.source or 'DIC frames'}: no frame has {min_valid:.0%} of its {frames.n_points} points valid "
            f"(best {best:.0%}): expected frames that cover the membrane"
        )
    fit = fit_frames(frames, frames.w, model.space, smoothing)
    used = enough & fit.fitted
    if not np.isfinite(fit.sigma) or fit.sigma <= 0:
        raise InputError(
            f"{frames.source or 'DIC frames'}: the W noise cannot be estimated from the fit residuals "
            f"({fit.sigma!r}): expected more points than the estimator's {model.n} unknowns"
        )
    Z = fit.coef[used]
    filled = np.where(frames.valid[used], frames.w[used], Z @ fit.basis.T)
    skipped = int(frames.n_frames - used.sum())
    if skipped:
        log.warning("%s: %d frame(s) with too few valid points left out", frames.source or "DIC frames", skipped)
    return FieldData(frames, used, fit, filled.mean(axis=0), Z.mean(axis=0), float(fit.sigma))


def inplane_check(data: FieldData, fvk) -> dict | None:
    """The measured mean in-plane displacements against the FvK in-plane equilibrium of the mean deflection.

    They follow from ``w`` and Poisson's ratio alone (the in-plane stiffness cancels, a uniform
    prestrain does not enter): a check of the model, not a source of the tension.
    """
    fr = data.frames
    used = data.used
    if not (np.isfinite(fr.u[used][fr.valid[used]]).all() and fr.strain_reference == "prestrained"):
        return None
    v = fr.valid[used]
    count = np.maximum(v.sum(axis=0), 1)
    mu = np.where(v, fr.u[used], 0.0).sum(axis=0) / count
    mv = np.where(v, fr.v[used], 0.0).sum(axis=0) / count
    uc, vc = fvk.inplane(data.mean_z)
    pu, pv = data.basis @ uc, data.basis @ vc
    seen = v.any(axis=0)
    scale = float(np.sqrt(np.mean(mu[seen] ** 2 + mv[seen] ** 2)))
    miss = float(np.sqrt(np.mean((mu - pu)[seen] ** 2 + (mv - pv)[seen] ** 2)))
    return {
        "rms_measured_m": scale,
        "rms_misfit_m": miss,
        "relative_misfit": miss / max(scale, 1e-300),
        "note": "U, V follow from w and Poisson's ratio (no prestrain, no stiffness): a model check, not the tension",
    }
