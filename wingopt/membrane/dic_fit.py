"""Smooth spline fits of DIC point fields, frame by frame: the deflection (or any field) as coefficients.

:func:`fit_frames` fits one field (``W``, ``U``, a strain) at the valid points of every frame by
least squares in a cubic-spline space, with a light curvature penalty ``smoothing`` (relative to
the data's normal matrix). The normal matrix of all points is formed and inverted once; a frame's
missing points are removed by a Woodbury downdate (a few points: ``O(n^2)`` per frame), or by a
Cholesky factorisation when many are missing. The noise std of the field is estimated from the
fit residuals (their median over the frames, with the fit's effective degrees of freedom removed).
Used by the virtual sensors (:mod:`.virtual_sensors`) and the full-field estimator
(:mod:`wingopt.estimation.fullfield`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from wingopt.fe import DXX, DYY, TensorSpace, assemble, separable
from wingopt.measurements.dic import DICFrames

__all__ = ["FrameFit", "fit_frames", "MIN_POINTS"]

MIN_POINTS = 0.25
"""A frame is fitted when it has at least this fraction of the space's dimension in valid points (+3)."""


@dataclass(frozen=True, eq=False)
class FrameFit:
    """Least-squares spline fits of one field over all frames.

    Attributes
    ----------
    space : TensorSpace
    coef : ndarray (F, n)
        Coefficients per frame; NaN rows for frames with too few valid points.
    sigma : float
        Noise std of the field estimated from the residuals.
    cov_unit : ndarray (n, n)
        Coefficient covariance per unit noise variance (every point valid).
    basis : ndarray (P, n)
        The space's basis at the points.
    """

    space: TensorSpace
    coef: np.ndarray
    sigma: float
    cov_unit: np.ndarray
    basis: np.ndarray

    @property
    def fitted(self) -> np.ndarray:
        """Frames with a fit (bool ``(F,)``)."""
        return np.all(np.isfinite(self.coef), axis=1)


def fit_frames(frames: DICFrames, values: np.ndarray, space: TensorSpace, smoothing: float = 1e-6) -> FrameFit:
    """Fit ``values`` (F, P) at the valid points of every frame with ``space`` (penalty ``smoothing``)."""
    B = space.basis_matrix(frames.x, frames.y).toarray()
    Lam = assemble(space, separable((1.0, DXX, DXX), (1.0, DYY, DYY))).toarray()
    G_all = B.T @ B
    lam = smoothing * np.trace(G_all) / max(np.trace(Lam), 1e-300)
    G0 = G_all + lam * Lam
    G0inv = np.linalg.inv(G0)
    F, n = values.shape[0], B.shape[1]
    coef = np.full((F, n), np.nan)
    rss, dof = [], []
    vals = np.where(frames.valid, values, 0.0)
    for k in range(F):
        ok = frames.valid[k]
        if ok.sum() < int(MIN_POINTS * n) + 3:
            continue
        rhs = B.T @ vals[k]
        bad = np.flatnonzero(~ok)
        if bad.size == 0:
            c = G0inv @ rhs
        elif bad.size < n // 8:  # Woodbury: (G0 - Bb^T Bb)^-1 = G0^-1 + G0^-1 Bb^T (I - Bb G0^-1 Bb^T)^-1 Bb G0^-1
            Bb = B[bad]
            U = Bb @ G0inv
            c0 = G0inv @ rhs
            c = c0 + U.T @ np.linalg.solve(np.eye(bad.size) - U @ Bb.T, U @ rhs)
        else:
            G = G0 - B[bad].T @ B[bad]
            c = sla.cho_solve(sla.cho_factor(G, check_finite=False), rhs, check_finite=False)
        coef[k] = c
        r = B[ok] @ c - values[k, ok]
        rss.append(r @ r)
        dof.append(ok.sum())
    cov_unit = G0inv @ G_all @ G0inv
    df = float(np.trace(G0inv @ G_all))
    sigma = float(np.sqrt(np.median(np.array(rss) / np.maximum(np.array(dof) - df, 1.0)))) if rss else float("nan")
    return FrameFit(space, coef, sigma, cov_unit, B)
