"""One-call figures of an identification run for a notebook: ``wo.plot_lift(run)``, ``wo.plot_field(run)``.

Each draws into ``ax`` when given (an axes the caller owns) or into a new
:class:`~matplotlib.figure.Figure`, and returns the figure; nothing is written.
"""

from __future__ import annotations

import numpy as np

from wingopt.errors import InputError
from wingopt.plots import pyplot as _pyplot
from wingopt.plots.field import draw_sensors, field_colors
from wingopt.plots.identify import plot_lift as _plot_lift

__all__ = ["plot_lift", "plot_field"]

GRID = (57, 29)
"""Points (x, y) of the drawn grid: ``load.csv``'s."""


def _title(run) -> str:
    if run.protocol.get("load_case"):
        return f"simulated {run.protocol['load_case']} · {run.method}"
    report = run.data_report or {}
    src = report.get("file") or report.get("frames_source") or run.measurements.source or "data"
    return f"{str(src).rsplit('/', 1)[-1]} · {run.method}"


def _check_run(run) -> None:
    if not all(hasattr(run, a) for a in ("result", "problem", "mean_field", "case")):
        raise InputError(f"run = {type(run).__name__}: expected the IdentifyRun that wingopt.identify returned")


def plot_lift(run, ax=None):
    """The lift history of ``run`` with its band and the reported lift ± its band (1 sd).

    Parameters
    ----------
    run : IdentifyRun
        From :func:`wingopt.identify`.
    ax : matplotlib axes, optional
        Draw into it (default: a new figure).

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn into (``ax.figure`` when ``ax`` is given).
    """
    _check_run(run)
    r = run.result
    truth = None if run.case is None else run.case.true_lift
    return _plot_lift(None, r.t, r.lift, r.lift_std, truth, _title(run), ax=ax, reported=r.reported_lift)


def plot_field(run, which: str | float = "mean", ax=None):
    """The pressure field of ``run`` on ``load.csv``'s grid, the sensors outlined.

    Parameters
    ----------
    run : IdentifyRun
    which : "mean", "std" or float
        ``"mean"``: the field behind the reported lift (``load.csv``); ``"std"``: its 1-sigma band;
        a time (s): the estimate at the sample nearest it.
    ax : matplotlib axes, optional
        Draw into it (default: a new figure).

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn into (``ax.figure`` when ``ax`` is given).
    """
    _check_run(run)
    X, Y = np.meshgrid(np.linspace(0, run.problem.width, GRID[0]), np.linspace(0, run.problem.height, GRID[1]))
    mf = run.mean_field()
    if isinstance(which, str) and which in ("mean", "std"):
        V = mf(X, Y) if which == "mean" else mf.std(X, Y)
        band = "" if mf.lift_std_N is None else f" ± {mf.lift_std_N:.2g} N (1 sd)"
        name = f"{'mean pressure' if which == 'mean' else '1-sigma band'} · lift {mf.lift_N:.4g} N{band}"
    elif isinstance(which, (int, float, np.number)) and not isinstance(which, bool) and np.isfinite(which):
        k = int(np.argmin(np.abs(np.asarray(run.result.t) - float(which))))
        V = run.load_field(k)(X, Y)
        name = f"pressure at t = {run.result.t[k]:.4g} s · lift {run.result.lift[k]:.4g} N"
    else:
        raise InputError(f"which = {which!r}: expected 'mean', 'std' or a time in s")
    if ax is None:
        fig, ax = _pyplot().subplots(figsize=(6.0, 3.4))
    else:
        fig = ax.figure
    kw = {"cmap": "magma", "vmin": 0.0} if which == "std" else field_colors(V)
    im = ax.pcolormesh(X * 1e3, Y * 1e3, V, shading="gouraud", **kw)
    draw_sensors(ax, run.problem.sensors)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(f"{_title(run)}\n{name}", fontsize="medium")
    fig.colorbar(im, ax=ax, label="Pa", shrink=0.8)
    return fig
