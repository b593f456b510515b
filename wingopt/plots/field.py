"""The pressure field behind the reported lift: the field, its band beside it, the sensors drawn on.

A one-signed field gets a sequential colour map from zero (``viridis``; a diverging map would spend
half its colours on values that do not occur); a field that changes sign a diverging one centred on
zero (``RdBu_r``). The band is sequential. Titles carry the lift and its 1-sigma band.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wingopt.plots import pyplot as _pyplot
from wingopt.plots import save as _save

__all__ = ["plot_field_band", "field_colors", "draw_sensors"]


def field_colors(values: np.ndarray) -> dict:
    """``pcolormesh`` keywords for ``values``: sequential from 0 when one-signed, diverging about 0 otherwise."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {"cmap": "viridis"}
    lo, hi = float(v.min()), float(v.max())
    if lo >= 0.0:
        return {"cmap": "viridis", "vmin": 0.0, "vmax": hi or 1.0}
    if hi <= 0.0:
        return {"cmap": "viridis_r", "vmin": lo or -1.0, "vmax": 0.0}
    lim = max(abs(lo), abs(hi))
    return {"cmap": "RdBu_r", "vmin": -lim, "vmax": lim}


def draw_sensors(ax, sensors, scale: float = 1e3) -> None:
    """Outline each stretch sensor's rectangle (``problem.sensors``) with its name."""
    from matplotlib.patches import Rectangle

    for s in sensors or ():
        x0, x1, y0, y1 = (scale * float(v) for v in s.rect)
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ec="w", lw=1.4))
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ec="k", lw=0.7, ls="--"))
        ax.annotate(s.name, (x1, y1), fontsize=7, ha="left", va="bottom", color="k")


def plot_field_band(
    path: Path | None,
    X: np.ndarray,
    Y: np.ndarray,
    P: np.ndarray,
    S: np.ndarray | None = None,
    *,
    lift: float | None = None,
    lift_std: float | None = None,
    sensors=(),
    truth: np.ndarray | None = None,
    title: str = "",
    label: str = "mean pressure",
):
    """The field ``P`` (Pa) on the grid ``X, Y`` (m), its band ``S`` beside it and the truth when known.

    Returns the figure (written to ``path`` unless ``None``).
    """
    panels = [(label, P, field_colors(P if truth is None else np.concatenate([P.ravel(), truth.ravel()])))]
    if S is not None and np.any(np.isfinite(S)):
        panels.append(("1-sigma band", S, {"cmap": "magma", "vmin": 0.0, "vmax": float(np.nanmax(S)) or 1.0}))
    if truth is not None:
        panels.append(("truth (same scale)", truth, panels[0][2]))
    fig, axes = _pyplot().subplots(1, len(panels), figsize=(5.0 * len(panels), 3.3), squeeze=False)
    for ax, (name, V, kw) in zip(axes[0], panels):
        im = ax.pcolormesh(X * 1e3, Y * 1e3, V, shading="gouraud", **kw)
        draw_sensors(ax, sensors)
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_title(name, fontsize="medium")
        fig.colorbar(im, ax=ax, label="Pa", shrink=0.8)
    head = [title] if title else []
    if lift is not None:
        head.append(f"lift {lift:.4g} N" + ("" if lift_std is None else f" ± {lift_std:.2g} N (1 sd)"))
    if head:
        fig.suptitle(" · ".join(head), fontsize="medium")
    return _save(fig, path, margins=True)
