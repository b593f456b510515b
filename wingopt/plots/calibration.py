"""Figures of a calibration (``wingopt calibrate``): the record the fit saw, and the fit's misfit over time."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wingopt.plots import pyplot as _pyplot
from wingopt.plots import save as _save

__all__ = ["plot_record", "plot_calibration"]


def plot_record(path: Path | None, t: np.ndarray, values: np.ndarray, names, title: str = "", ax=None):
    """Each sensor's output over time (the calibration record: a release, a pluck or a tap)."""
    if ax is None:
        fig, ax = _pyplot().subplots(figsize=(7.6, 3.4))
        own = True
    else:
        fig, own = ax.figure, False
    v = np.asarray(values, dtype=float)
    for j, name in enumerate(names):
        ax.plot(t, v[:, j], lw=1.0, label=str(name))
    ax.set_xlabel("t (s)")
    ax.set_ylabel("sensor output")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize="small", ncols=min(len(names), 4))
    if title:
        ax.set_title(title, fontsize="medium")
    return _save(fig, path if own else None)  # tight: a two-line title


def plot_calibration(tmp: Path, run, title: str) -> dict:
    """The figures of a :class:`~wingopt.workflows.calibrate.CalibrationRun` into ``tmp``; returns
    ``{file name: caption}``."""
    from wingopt.plots.misfit import plot_misfit

    meas, cal = run.measurements, run.calibration
    p, sd = cal.parameters, cal.parameters_std
    pars = ", ".join(f"{k} {v:.4g} ± {sd.get(k, float('nan')):.2g}" for k, v in p.items()) + " (1 sd)"
    plot_record(tmp / "record.png", meas.t, meas.values, meas.sensor_names, f"{title}\n{pars}")
    out = {"record.png": "the calibration record and the identified parameters (1 sd)"}
    adequacy = cal.info.get("adequacy", {})
    if "segments_t_s" in adequacy:
        plot_misfit(tmp / "misfit.png", adequacy, title)
        out["misfit.png"] = "the fit's chi-square per datum per segment of the record (1: explained to the noise)"
    return out
