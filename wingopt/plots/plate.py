"""Figures of the plate wing: the layout (Figure 5.4 reconstructed) and mode shapes.

Built on :class:`matplotlib.figure.Figure` directly (no pyplot state), so they work under any
backend and in threads; :func:`wingopt.plots.save` writes them (``tight=False``: they lay
themselves out).
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from wingopt.problem.plate import PlateProblem

__all__ = ["layout_figure", "modes_figure"]


def layout_figure(problem: PlateProblem, mesh: tuple[int, int] | None = (7, 31)) -> Figure:
    """Plan view: skin, battens (black), patch pairs (grey, labelled) and the coarsest mesh lines."""
    W, L = problem.width, problem.length
    fig = Figure(figsize=(3.6, 8.0), constrained_layout=True)
    ax = fig.add_subplot()
    ax.add_patch(Rectangle((0, 0), W, L, facecolor="#9a9a9a", edgecolor="none", label="skin"))
    for i, b in enumerate(problem.battens):
        x0, x1, y0, y1 = b.rect
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor="black", label="battens" if i == 0 else None))
    for i, p in enumerate(problem.patches):
        x0, x1, y0, y1 = p.rect
        ax.add_patch(
            Rectangle(
                (x0, y0),
                x1 - x0,
                y1 - y0,
                facecolor="#e6e6e6",
                edgecolor="black",
                lw=0.6,
                label="patch pairs" if i == 0 else None,
            )
        )
        ax.text((x0 + x1) / 2, (y0 + y1) / 2, p.name, ha="center", va="center", fontsize=7, rotation=0)
    if mesh is not None:
        for x in np.linspace(0, W, mesh[0]):
            ax.axvline(x, color="white", lw=0.3, alpha=0.5)
        for y in np.linspace(0, L, mesh[1]):
            ax.axhline(y, color="white", lw=0.3, alpha=0.5)
    ax.plot([0, W], [L, L], color="tab:red", lw=3, label="clamped root")
    ax.set_xlim(-0.005, W + 0.005)
    ax.set_ylim(-0.005, L + 0.01)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m), chord")
    ax.set_ylabel("y (m), span (tip at 0)")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=2, fontsize=7, frameon=False)
    ax.set_title(f"{problem.name}: layout" + (f" ({mesh[0]}x{mesh[1]} mesh lines)" if mesh else ""), fontsize=9)
    return fig


def modes_figure(model, count: int = 4) -> Figure:
    """Contour plots of the lowest ``count`` mode shapes with their frequency and kind."""
    freqs, shapes = model.modes(count)
    fig = Figure(figsize=(2.0 * count, 6.0), constrained_layout=True)
    for k in range(count):
        ax = fig.add_subplot(1, count, k + 1)
        X, Y, w = model.evaluate_grid(shapes[:, k], nx=31, ny=121)
        w = w / np.abs(w).max()
        ax.contourf(X, Y, w, levels=np.linspace(-1, 1, 21), cmap="RdBu_r")
        ax.contour(X, Y, w, levels=[0.0], colors="k", linewidths=0.6)
        kind, order = model.classify_mode(shapes[:, k])
        ax.set_title(f"{freqs[k]:.2f} Hz\n{kind} {order}", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xticks([0, model.problem.width])
        if k:
            ax.set_yticks([])
    nx, ny = model.problem.nodes
    fig.suptitle(f"mode shapes, {nx}x{ny} mesh (w normalised; black: nodal lines)", fontsize=9)
    return fig
