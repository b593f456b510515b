"""Virtual stretch sensors from DIC frames: the seed's route (spec §2, §10).

The package's stretch sensor over a rectangle ``S`` of area ``A`` is
``s = alpha/(2A) ∫_S (w_x^2 + w_y^2)`` (:mod:`wingopt.membrane.sensors`). From DIC frames it is
emulated three ways (``kind``):

``"slope"``
    The definition itself: a smooth fit of the deflection ``W`` (zero on the frame), then
    ``s = z^T C z`` with the package's exact sensor matrices; the fit's noise bias
    ``sigma^2 tr(C Cov)`` (always positive: slopes squared) is subtracted, ``sigma`` estimated from
    the fit residuals. Needs only ``W``: the route for DICe, whose strains lack ``w``.
``"strain"`` (the seed's)
    ``s_DIC = alpha/A ∫_S (E_xx + E_yy)``, the rectangle mean of the trace of the surface Lagrange
    strain. With the FvK strains ``E_xx + E_yy = (u_x + v_y) + (w_x^2 + w_y^2)/2 +
    (u_x^2 + u_y^2 + v_x^2 + v_y^2)/2``, so ``s_DIC = s + alpha mean(u_x + v_y) + alpha mean(quadratic)``:
    it equals the package's sensor only when the in-plane stretch of the membrane is negligible.
    Requires ``strain_kind = "surface"`` and ``strain_reference = "prestrained"``.
``"strain_minus_inplane"``
    ``"strain"`` less ``alpha mean(u_x + v_y)`` from smooth fits of ``U`` and ``V`` (zero on the frame).

Integration (``method``): ``"fit"`` (default) fits each frame's valid points by least squares with
a cubic-spline space on the wing (``nodes``, a light curvature penalty) and integrates the fit
exactly over the rectangle; ``"points"`` (strain kinds only) is a nearest-valid-point quadrature
(the rectangle sampled 24 x 24, each sample given the value of its nearest valid DIC point).
A frame whose rectangle (enlarged by half the point spacing) holds fewer than ``min_fraction`` of
its points valid, or fewer than 3, gives NaN for that sensor (logged).

``noise_std`` of the result (``"fit"`` only): the propagated fit noise, ``sigma sqrt(m^T Cov m)``
for the linear strain routes and ``2 sigma sqrt(c^T C Cov C c)`` (median over the frames: it grows
with the slope) for ``"slope"``, with ``sigma`` each field's residual noise; ``None`` for ``"points"``.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.spatial import cKDTree

from wingopt.errors import InputError
from wingopt.fe import EdgeCondition
from wingopt.measurements.dic import DICFrames
from wingopt.measurements.series import Measurements
from wingopt.membrane.dic_fit import fit_frames
from wingopt.membrane.model import membrane_space
from wingopt.membrane.sensors import StretchSensors

__all__ = ["virtual_sensors", "KINDS", "METHODS"]

log = logging.getLogger(__name__)

KINDS = ("slope", "strain", "strain_minus_inplane")
METHODS = ("fit", "points")


def _region_counts(frames: DICFrames, rects) -> tuple[np.ndarray, np.ndarray]:
    """Valid and total point counts ``(F, p)``, ``(p,)`` in each rectangle enlarged by half the spacing."""
    xs, ys = np.unique(frames.x), np.unique(frames.y)
    hx = 0.5 * np.median(np.diff(xs)) if xs.size > 1 else 0.0
    hy = 0.5 * np.median(np.diff(ys)) if ys.size > 1 else 0.0
    valid, total = [], []
    for x0, x1, y0, y1 in rects:
        inside = (frames.x >= x0 - hx) & (frames.x <= x1 + hx) & (frames.y >= y0 - hy) & (frames.y <= y1 + hy)
        valid.append(frames.valid[:, inside].sum(axis=1))
        total.append(inside.sum())
    return np.stack(valid, axis=1), np.array(total)


def _rect_means(space, rects, gains, dx: int = 0, dy: int = 0) -> np.ndarray:
    """``(p, n)``: rows ``alpha/A ∫_S d(phi)`` (exact Gauss quadrature on the rectangle's cells)."""
    rows = []
    for (x0, x1, y0, y1), g in zip(rects, gains):
        xq, yq, wq = space.cells((x0, x1, y0, y1)).quadrature(5)
        B = space.basis_matrix(xq.ravel(), yq.ravel(), dx, dy)
        rows.append(g * (B.T @ wq.ravel()) / ((x1 - x0) * (y1 - y0)))
    return np.array(rows)


def _points_means(frames: DICFrames, values: np.ndarray, rects, gains, samples: int = 24) -> np.ndarray:
    """Nearest-valid-point quadrature of ``values`` (F, P) over each rectangle -> (F, p)."""
    tree = cKDTree(np.column_stack([frames.x, frames.y]))
    out = np.empty((values.shape[0], len(rects)))
    for i, ((x0, x1, y0, y1), g) in enumerate(zip(rects, gains)):
        sx = x0 + (np.arange(samples) + 0.5) * (x1 - x0) / samples
        sy = y0 + (np.arange(samples) + 0.5) * (y1 - y0) / samples
        S = np.column_stack([np.repeat(sx, samples), np.tile(sy, samples)])
        _, idx = tree.query(S, k=min(8, frames.n_points))
        V = frames.valid[:, idx]  # (F, S, k)
        first = np.argmax(V, axis=2)
        pick = np.take_along_axis(idx[None, :, :].repeat(V.shape[0], 0), first[..., None], 2)[..., 0]
        val = np.take_along_axis(values, pick, axis=1)
        has = V.any(axis=2)
        with np.errstate(invalid="ignore", divide="ignore"):
            out[:, i] = g * np.where(has, val, 0.0).sum(1) / has.sum(1)
    return out


def _check_kind(frames: DICFrames, kind: str, method: str) -> None:
    """Refuse a kind and method the frames cannot give (strains need surface strains on the prestrained state)."""
    if kind not in KINDS or method not in METHODS:
        raise InputError(f"kind = {kind!r}, method = {method!r}: expected kind in {KINDS} and method in {METHODS}")
    if kind == "slope" and method != "fit":
        raise InputError("kind = 'slope': expected method = 'fit' (slopes need a smooth fit of W)")
    if kind == "slope":
        return
    if frames.strain_kind != "surface":
        raise InputError(
            f"{frames.source}: strain_kind = {frames.strain_kind!r}: kind = {kind!r} needs surface Lagrange "
            "strains with the w terms (DICe's VSG strains are in-plane only); use kind = 'slope'"
        )
    if frames.strain_reference != "prestrained":
        raise InputError(
            f"{frames.source}: strain_reference = {frames.strain_reference!r}: kind = {kind!r} needs strains "
            "referenced to the prestrained membrane; use kind = 'slope'"
        )


def _slope_values(frames: DICFrames, zero, specs, smoothing: float) -> tuple[np.ndarray, np.ndarray]:
    """The sensors' outputs ``c^T C_i c`` on each frame's smooth fit of W (its noise bias removed), and their noise."""
    fit = fit_frames(frames, frames.w, zero, smoothing)
    C = [Ci.toarray() for Ci in StretchSensors.assemble(zero, specs).matrices]
    CZ = [fit.coef @ Ci for Ci in C]  # rows c^T C_i
    values = np.stack([np.einsum("fi,fi->f", fit.coef, cz) for cz in CZ], axis=1)
    bias = np.array([fit.sigma**2 * np.sum(Ci * fit.cov_unit) for Ci in C])
    values = values - bias[None, :]
    noise = np.array(
        [2 * fit.sigma * np.sqrt(np.nanmedian(np.einsum("fi,ij,fj->f", cz, fit.cov_unit, cz))) for cz in CZ]
    )
    log.info("virtual sensors (slope): W noise %.3g m, bias removed %s", fit.sigma, np.array2string(bias, precision=3))
    return values, noise


def virtual_sensors(
    frames: DICFrames,
    problem,
    *,
    sensors=None,
    kind: str = "slope",
    method: str = "fit",
    nodes: tuple[int, int] = (17, 9),
    smoothing: float = 1e-6,
    min_fraction: float = 0.5,
) -> Measurements:
    """Emulate stretch sensors from DIC frames (module docstring): one value per frame and sensor.

    Parameters
    ----------
    frames : DICFrames
    problem : MembraneProblem
        The wing (extent) and, unless ``sensors`` is given, its sensors (names, rectangles, gains).
    sensors : sequence of StretchSensorSpec, optional
    kind : {"slope", "strain", "strain_minus_inplane"}
    method : {"fit", "points"}
    nodes : (int, int)
        Mesh of the fitting space (default 17 x 9).

    Returns
    -------
    Measurements
        ``t`` the frame times, NaN for a frame whose sensor region has too few valid points.
    """
    specs = tuple(problem.sensors if sensors is None else sensors)
    _check_kind(frames, kind, method)
    rects = [tuple(s.rect) for s in specs]
    gains = [s.gain for s in specs]
    counts, total = _region_counts(frames, rects)
    if np.any(total == 0):
        i = int(np.argmin(total))
        raise InputError(
            f"sensor {specs[i].name} rect = {list(rects[i])}: no DIC point inside: expected a region the DIC covers"
        )
    W, H = problem.width, problem.height
    zero = membrane_space(W, H, nodes)
    noise = None
    if kind == "slope":
        values, noise = _slope_values(frames, zero, specs, smoothing)
    else:
        trace = frames.exx + frames.eyy
        if method == "fit":
            free = membrane_space(W, H, nodes, EdgeCondition.FREE)
            fit, M = fit_frames(frames, trace, free, smoothing), _rect_means(free, rects, gains)
            values = fit.coef @ M.T
            noise = fit.sigma * np.sqrt(np.einsum("pi,ij,pj->p", M, fit.cov_unit, M))
        else:
            values = _points_means(frames, trace, rects, gains)
        if kind == "strain_minus_inplane":
            for field, d in ((frames.u, (1, 0)), (frames.v, (0, 1))):
                fit, M = fit_frames(frames, field, zero, smoothing), _rect_means(zero, rects, gains, *d)
                values = values - fit.coef @ M.T
                if noise is not None:
                    noise = np.hypot(noise, fit.sigma * np.sqrt(np.einsum("pi,ij,pj->p", M, fit.cov_unit, M)))
    few = (counts < np.maximum(3, min_fraction * total)[None, :]) | ~np.isfinite(values)
    if few.any():
        log.warning(
            "%s: %d frame-sensor values with too few valid DIC points set to NaN", frames.source, int(few.sum())
        )
    values = np.where(few, np.nan, values)
    src = f"DIC virtual sensors ({kind}, {method}) from {frames.source}"
    return Measurements(frames.t, values, tuple(s.name for s in specs), noise, src)
