"""Figures written by the commands, built on :class:`matplotlib.figure.Figure`.

No pyplot state and no global backend switch: a notebook's inline display and a user's chosen
backend are left alone, and the figures render to PNG through matplotlib's own canvas for the
file type. Every plotting function returns its figure; the single-panel ones accept ``ax=`` to
draw into an axes the caller owns (then nothing is written).
"""

from __future__ import annotations

from pathlib import Path


class _Figures:
    """The two pyplot calls the plotting modules use, on plain :class:`~matplotlib.figure.Figure`."""

    @staticmethod
    def subplots(nrows: int = 1, ncols: int = 1, *, figsize=None, **kw):
        from matplotlib.figure import Figure

        fig = Figure(figsize=figsize)
        return fig, fig.subplots(nrows, ncols, **kw)

    @staticmethod
    def figure(figsize=None):
        from matplotlib.figure import Figure

        return Figure(figsize=figsize)


def pyplot() -> type[_Figures]:
    """``subplots``/``figure`` factories for :class:`~matplotlib.figure.Figure` (matplotlib imported on
    first use: the commands that draw nothing do not pay for it). Kept under its old name."""
    return _Figures


def save(fig, path: Path | None, tight: bool = True, dpi: int = 110):
    """Lay out (unless ``tight=False``) and write ``fig`` as a PNG (110 dpi unless given); returns the figure."""
    if path is None:
        return fig
    if tight:
        fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    return fig
