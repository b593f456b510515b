"""The sensor-design figure: designed rectangles over the predicted load-error field.

The field is :func:`wingopt.design.predicted_error_field` of the design (where the layout leaves
the load unresolved); the caller computes it and hands it here with the design's result.
"""

from __future__ import annotations

from pathlib import Path

from wingopt.plots import save as _save

__all__ = ["plot_layout"]


def _rectangle(r, **style):
    from matplotlib.patches import Rectangle

    return Rectangle((r[0] * 1e3, r[2] * 1e3), (r[1] - r[0]) * 1e3, (r[3] - r[2]) * 1e3, fill=False, **style)


def plot_layout(path: Path | None, result, field, default_rects=None, title: str | None = None):
    """Figure of ``result.rects`` (and optionally the problem's own, dashed) over ``field = (X, Y, E)``.

    ``result`` is a :class:`~wingopt.design.DesignResult`; written as a PNG at 120 dpi to ``path``
    (``None``: only returned).
    """
    from matplotlib.figure import Figure

    X, Y, E = field
    prob = result.problem
    fig = Figure(figsize=(7.5, 4.2), layout="constrained")
    ax = fig.add_subplot()
    im = ax.pcolormesh(X * 1e3, Y * 1e3, E, shading="gouraud", cmap="magma_r", vmin=0)
    fig.colorbar(im, ax=ax, label="predicted |P - P^| / RMS P")
    for r in () if default_rects is None else default_rects:
        ax.add_patch(_rectangle(r, ec="0.6", ls="--", lw=1.2))
    for i, r in enumerate(result.rects):
        ax.add_patch(_rectangle(r, ec="c", lw=2))
        ax.text((r[0] + r[1]) / 2 * 1e3, (r[2] + r[3]) / 2 * 1e3, f"S{i + 1}", color="c", ha="center", va="center")
    ax.set_xlim(0, prob.width * 1e3)
    ax.set_ylim(0, prob.height * 1e3)
    ax.set_aspect("equal")
    ax.set_xlabel("x (chord), mm")
    ax.set_ylabel("y (span), mm")
    value = result.predictions.get("risk_relative_load_error")
    ax.set_title(
        title or f"{result.count} sensors ({result.settings.criterion}); predicted mean load error {value:.3f}"
    )
    return _save(fig, path, tight=False, dpi=120)
