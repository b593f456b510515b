"""Synthetic DIC frames from a simulated Föppl–von Kármán membrane.

The frames are what a stereo DIC system referenced to the mounted, prestrained, flat membrane
would report at a grid of points: ``W = w``, ``U = u``, ``V = v`` (the FvK in-plane equilibrium
displacements, :meth:`~wingopt.membrane.fvk.FvKMembrane.inplane`) and the surface Lagrange strains
of the load-induced deformation::

    E_xx = u_x + (u_x^2 + v_x^2 + w_x^2)/2,   E_yy = v_y + (u_y^2 + v_y^2 + w_y^2)/2
    E_xy = (u_y + v_x + u_x u_y + v_x v_y + w_x w_y)/2

plus Gaussian noise (default 10 µm on U, V, W and 1e-4 on the strains, independent per point)
and a random fraction of points missing in every frame (default 2 %).

:func:`exact_sensor_parts` gives the exact integrals over sensor rectangles that the virtual
sensors are measured against. The writers of the DIC layouts (DICe solution files, plain CSV
frames, NPZ) are :mod:`wingopt.results.dic_files`.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from wingopt.errors import InputError
from wingopt.measurements.dic import DICFrames

__all__ = ["dic_grid", "membrane_fields", "synthesize_frames", "exact_sensor_parts"]

log = logging.getLogger(__name__)


def dic_grid(width: float, height: float, shape: tuple[int, int] = (40, 20)) -> tuple[np.ndarray, np.ndarray]:
    """Cell centres of a ``shape = (nx, ny)`` grid on the wing (y fastest): ``x, y`` of shape ``(nx ny,)``."""
    nx, ny = shape
    if nx < 2 or ny < 2:
        raise InputError(f"DIC grid = {shape!r}: expected at least 2 x 2 points")
    xs, ys = (np.arange(nx) + 0.5) * width / nx, (np.arange(ny) + 0.5) * height / ny
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    return X.ravel(), Y.ravel()


def membrane_fields(fvk, Z: np.ndarray, x: np.ndarray, y: np.ndarray) -> dict[str, np.ndarray]:
    """Exact ``u, v, w, exx, eyy, exy`` (F, P) at points for deflection coefficients ``Z`` (F, n).

    Also returns the in-plane coefficient histories ``"uc", "vc"`` (F, n) and the in-plane
    (2-D, DICe's VSG) strains ``"exx_inplane", "eyy_inplane", "exy_inplane"`` (no ``w`` terms).
    """
    Z = np.atleast_2d(np.asarray(Z, float))
    UC, VC = np.empty_like(Z), np.empty_like(Z)
    for k, z in enumerate(Z):
        UC[k], VC[k] = fvk.inplane(z)
    sp_ = fvk.space
    B = {d: sp_.basis_matrix(x, y, *d) for d in ((0, 0), (1, 0), (0, 1))}

    def ev(C, d):
        return np.asarray(B[d] @ C.T).T

    ux, uy, vx, vy = ev(UC, (1, 0)), ev(UC, (0, 1)), ev(VC, (1, 0)), ev(VC, (0, 1))
    wx, wy = ev(Z, (1, 0)), ev(Z, (0, 1))
    plane = {
        "exx_inplane": ux + 0.5 * (ux**2 + vx**2),
        "eyy_inplane": vy + 0.5 * (uy**2 + vy**2),
        "exy_inplane": 0.5 * (uy + vx + ux * uy + vx * vy),
    }
    return {
        "u": ev(UC, (0, 0)),
        "v": ev(VC, (0, 0)),
        "w": ev(Z, (0, 0)),
        "exx": plane["exx_inplane"] + 0.5 * wx**2,
        "eyy": plane["eyy_inplane"] + 0.5 * wy**2,
        "exy": plane["exy_inplane"] + 0.5 * wx * wy,
        "uc": UC,
        "vc": VC,
        **plane,
    }


def synthesize_frames(
    fvk,
    t: np.ndarray,
    Z: np.ndarray,
    *,
    grid: tuple[int, int] = (40, 20),
    points=None,
    noise_displacement: float = 1e-5,
    noise_strain: float = 1e-4,
    missing: float = 0.02,
    seed: int | None = 0,
    source: str = "synthetic FvK",
    strain_kind: str = "surface",
) -> DICFrames:
    """DIC frames of the FvK membrane ``fvk`` along the deflection history ``Z`` (F, n) at times ``t``.

    Parameters
    ----------
    grid : (nx, ny)
        Points at the cell centres of this grid (ignored when ``points = (x, y)`` is given).
    noise_displacement, noise_strain : float
        Standard deviations (m; dimensionless) of independent Gaussian noise.
    missing : float
        Fraction of points invalid in each frame, drawn at random (their values are NaN).
    strain_kind : {"surface", "inplane"}
        The surface Lagrange strains (VIC-3D's), or the in-plane ones without the ``w`` terms (DICe's).
    """
    t = np.asarray(t, float)
    Z = np.atleast_2d(np.asarray(Z, float))
    if Z.shape[0] != t.size:
        raise InputError(f"Z has {Z.shape[0]} frames for {t.size} times: expected one deflection per time")
    if strain_kind not in ("surface", "inplane"):
        raise InputError(f"strain_kind = {strain_kind!r}: expected 'surface' or 'inplane'")
    if not (0 <= missing < 1 and noise_displacement >= 0 and noise_strain >= 0):
        raise InputError(
            f"missing = {missing!r}, noise = {noise_displacement!r}, {noise_strain!r}: expected [0, 1) and >= 0"
        )
    p = fvk.problem
    x, y = (
        dic_grid(p.width, p.height, grid)
        if points is None
        else (np.asarray(points[0], float), np.asarray(points[1], float))
    )
    f = membrane_fields(fvk, Z, x, y)
    rng = np.random.default_rng(seed)
    F, P = Z.shape[0], x.size
    out = {}
    for k in ("u", "v", "w", "exx", "eyy", "exy"):
        sd = noise_displacement if k in "uvw" else noise_strain
        exact = f[k + "_inplane"] if strain_kind == "inplane" and k.startswith("e") else f[k]
        out[k] = exact + sd * rng.standard_normal((F, P))
    valid = rng.random((F, P)) >= missing
    for a in out.values():
        a[~valid] = np.nan
    return DICFrames(
        x, y, t, **out, valid=valid, source=source, units="m", strain_reference="prestrained", strain_kind=strain_kind
    )


def _rect_quadrature(space, rect, order: int = 5):
    cells = space.cells(tuple(rect))
    xq, yq, wq = cells.quadrature(order)
    return xq.ravel(), yq.ravel(), wq.ravel()


def exact_sensor_parts(fvk, Z: np.ndarray, rects: Sequence[Sequence[float]], UC=None, VC=None) -> dict[str, np.ndarray]:
    """Exact rectangle means of the parts of the strain trace, each ``(F, p)``.

    ``slope = (1/2A) ∫ (w_x^2 + w_y^2)`` (the package's stretch sensor with alpha = 1),
    ``inplane = (1/A) ∫ (u_x + v_y)``, ``quadratic = (1/2A) ∫ (u_x^2 + u_y^2 + v_x^2 + v_y^2)`` and
    ``trace = (1/A) ∫ (E_xx + E_yy) = slope + inplane + quadratic``. Gauss quadrature on the cells
    of the rectangle (exact for the spline fields).
    """
    Z = np.atleast_2d(np.asarray(Z, float))
    if UC is None or VC is None:
        UC, VC = np.empty_like(Z), np.empty_like(Z)
        for k, z in enumerate(Z):
            UC[k], VC[k] = fvk.inplane(z)
    sp_ = fvk.space
    res = {k: np.empty((Z.shape[0], len(rects))) for k in ("slope", "inplane", "quadratic", "trace")}
    for i, r in enumerate(rects):
        xq, yq, wq = _rect_quadrature(sp_, r)
        A = (r[1] - r[0]) * (r[3] - r[2])
        Bx, By = sp_.basis_matrix(xq, yq, 1, 0), sp_.basis_matrix(xq, yq, 0, 1)
        d = {n: np.asarray(Bx @ C.T) for n, C in (("u", UC), ("v", VC), ("w", Z))}
        e = {n: np.asarray(By @ C.T) for n, C in (("u", UC), ("v", VC), ("w", Z))}
        res["slope"][:, i] = wq @ (d["w"] ** 2 + e["w"] ** 2) / (2 * A)
        res["inplane"][:, i] = wq @ (d["u"] + e["v"]) / A
        res["quadratic"][:, i] = wq @ (d["u"] ** 2 + e["u"] ** 2 + d["v"] ** 2 + e["v"] ** 2) / (2 * A)
    res["trace"] = res["slope"] + res["inplane"] + res["quadratic"]
    return res
