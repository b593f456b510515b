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


MARGINS = (1.0, 0.55, 0.5, 0.45)
"""Fixed margins (inches: left, bottom, right, top) of :func:`save`'s ``margins=True``: room for an
axis label, the tick labels and a title (and a suptitle's line at the top)."""


def save(fig, path: Path | None, tight: bool = True, dpi: int = 110, margins: bool = False):
    """Lay out and write ``fig`` as a PNG (110 dpi unless given); returns the figure.

    ``margins``: the fixed :data:`MARGINS` (a third of the time of ``tight``'s layout, which draws the
    figure once more to measure it: ~0.15 s a figure, half of an identification's outputs); else
    ``tight``: :meth:`~matplotlib.figure.Figure.tight_layout`; else as built.
    """
    if path is None:
        return fig
    if margins:
        w, h = fig.get_size_inches()
        left, bottom, right, top = MARGINS
        fig.subplots_adjust(left=left / w, bottom=bottom / h, right=1 - right / w, top=1 - top / h, wspace=0.35)
    elif tight:
        fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    return fig
