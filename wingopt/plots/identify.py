"""Figures of a load identification: pressure field, lift history with its band, error histories."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wingopt.plots import pyplot as _pyplot
from wingopt.plots import save as _save

__all__ = ["plot_load_field", "plot_lift", "plot_errors"]


def plot_load_field(
    path: Path | None,
    X: np.ndarray,
    Y: np.ndarray,
    estimate: np.ndarray,
    truth: np.ndarray | None = None,
    title: str = "",
):
    """Estimated pressure (and the true one beside it, same colour scale) on a grid, Pa; returns the figure."""
    plt = _pyplot()
    panels = [("estimate", estimate)] + ([("truth", truth)] if truth is not None else [])
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 3.2), squeeze=False)
    vals = np.concatenate([p[1].ravel() for p in panels])
    lim = float(np.max(np.abs(vals))) or 1.0
    for ax, (name, P) in zip(axes[0], panels):
        im = ax.pcolormesh(X * 1e3, Y * 1e3, P, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="gouraud")
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_title(f"pressure, {name}")
        fig.colorbar(im, ax=ax, label="Pa", shrink=0.8)
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def _axes(ax):
    """``(figure, axes, own)``: a new 6.4 x 3.4 in figure unless the caller gave ``ax``."""
    if ax is not None:
        return ax.figure, ax, False
    fig, ax = _pyplot().subplots(figsize=(6.4, 3.4))
    return fig, ax, True


def _first_window(ax, first_window_s: float | None) -> None:
    if first_window_s:
        ax.axvspan(0, first_window_s, color="0.85", alpha=0.6, lw=0, label="first window (smoothed, known at its end)")


def plot_lift(
    path: Path | None,
    t: np.ndarray,
    lift: np.ndarray,
    std: np.ndarray | None = None,
    truth: float | None = None,
    title: str = "",
    first_window_s: float | None = None,
    ax=None,
):
    """Lift history with its 1-sigma band and the true lift when known; returns the figure.

    ``ax``: draw into this axes (nothing is written; ``path`` may be ``None``).

    ``first_window_s`` shades the first MHE window, whose samples carry the first window's
    (smoothed) estimate, available only at the window's end.
    """
    fig, ax, own = _axes(ax)
    _first_window(ax, first_window_s)
    ax.plot(t, lift, color="C0", label="estimate")
    if std is not None and np.any(np.isfinite(std)):
        ax.fill_between(t, lift - std, lift + std, color="C0", alpha=0.25, label="1-sigma band")
    if truth is not None:
        ax.axhline(truth, color="k", ls="--", lw=1, label="truth")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("lift (N)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best")
    if title:
        ax.set_title(title)
    return _save(fig, path if own else None)


def plot_errors(
    path: Path | None,
    t: np.ndarray,
    load_error: np.ndarray,
    deflection_error: np.ndarray,
    title: str = "",
    first_window_s: float | None = None,
    ax=None,
):
    """Relative L2 errors of load and deflection over time (log scale); returns the figure (``ax`` as
    in :func:`plot_lift`)."""
    fig, ax, own = _axes(ax)
    _first_window(ax, first_window_s)
    ax.semilogy(t, load_error, label="load")
    ax.semilogy(t, deflection_error, label="deflection")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("relative L2 error")
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="best")
    if title:
        ax.set_title(title)
    return _save(fig, path if own else None)
