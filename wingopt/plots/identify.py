"""Figures of a load identification: pressure field, lift history with its band, error histories."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wingopt.plots import pyplot as _pyplot
from wingopt.plots import save as _save

__all__ = ["plot_load_field", "plot_lift", "plot_errors"]


def plot_load_field(
    path: Path, X: np.ndarray, Y: np.ndarray, estimate: np.ndarray, truth: np.ndarray | None = None, title: str = ""
) -> Path:
    """Estimated pressure (and the true one beside it, same colour scale) on a grid, Pa."""
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


def _first_window(ax, first_window_s: float | None) -> None:
    if first_window_s:
        ax.axvspan(0, first_window_s, color="0.85", alpha=0.6, lw=0, label="first window (smoothed, known at its end)")


def plot_lift(
    path: Path,
    t: np.ndarray,
    lift: np.ndarray,
    std: np.ndarray | None = None,
    truth: float | None = None,
    title: str = "",
    first_window_s: float | None = None,
) -> Path:
    """Lift history with its 1-sigma band and the true lift when known.

    ``first_window_s`` shades the first MHE window, whose samples carry the first window's
    (smoothed) estimate, available only at the window's end.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 3.4))
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
    return _save(fig, path)


def plot_errors(
    path: Path,
    t: np.ndarray,
    load_error: np.ndarray,
    deflection_error: np.ndarray,
    title: str = "",
    first_window_s: float | None = None,
) -> Path:
    """Relative L2 errors of load and deflection over time (log scale)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 3.4))
    _first_window(ax, first_window_s)
    ax.semilogy(t, load_error, label="load")
    ax.semilogy(t, deflection_error, label="deflection")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("relative L2 error")
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="best")
    if title:
        ax.set_title(title)
    return _save(fig, path)
