"""Misfit figure of an identification: chi-square per datum per segment, the tolerance, flagged spans."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wingopt.plots import pyplot as _pyplot
from wingopt.plots import save as _save

__all__ = ["plot_misfit", "plot_sensor_means", "plot_sensor_fit"]


def plot_misfit(path: Path, adequacy: dict, title: str = "") -> Path:
    """Bar per segment of ``adequacy`` (:meth:`Adequacy.as_dict`), red where the data contradict the model."""
    plt = _pyplot()
    t = np.asarray(adequacy["segments_t_s"], dtype=float)
    chi = np.asarray(adequacy["segments_chi2_per_datum"], dtype=float)
    width = float(np.median(np.diff(t))) if t.size > 1 else 0.05
    fig, ax = plt.subplots(figsize=(6.4, 3.0))
    ax.bar(t, chi, width=0.9 * width, align="edge", color="C0", label="chi-square per datum")
    for a, b in adequacy["misfit_segments_s"]:
        ax.axvspan(a, b, color="C3", alpha=0.3)
    ax.axhline(1.0, color="k", lw=1)
    ax.axhline(1.0 + adequacy["tolerance"], color="k", ls="--", lw=1, label="tolerance")
    ax.set_yscale("log")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("chi-square / datum")
    verdict = "adequate" if adequacy["model_adequate"] else f"INADEQUATE, band x{adequacy['band_inflation']:.2f}"
    ax.set_title(f"{title} · model {verdict}" if title else f"model {verdict}")
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="best")
    return _save(fig, path, margins=True)


def plot_sensor_means(path: Path, info: dict, names, title: str = "") -> Path:
    """A steady record's data and fit: each sensor's mean with its standard error, the fitted static
    outputs, and the RMS fluctuation about the mean (what buffeting and noise add)."""
    plt = _pyplot()
    mean = np.asarray(info["sensor_mean"], dtype=float)
    se = np.asarray(info["sensor_mean_std"], dtype=float)
    fit = np.asarray(info["sensor_fit"], dtype=float)
    rms = np.asarray(info["fluctuation_rms"], dtype=float) * np.abs(mean)
    x = np.arange(mean.size)
    fig, ax = plt.subplots(figsize=(6.4, 3.0))
    ax.bar(x - 0.2, mean, width=0.4, yerr=rms, color="C0", alpha=0.5, label="record mean (bar: RMS fluctuation)")
    ax.errorbar(x - 0.2, mean, yerr=2 * se, fmt="none", ecolor="k", capsize=4, label="2 standard errors")
    ax.bar(x + 0.2, fit, width=0.4, color="C1", label="static fit")
    ax.set_xticks(x, list(names))
    ax.set_ylabel("sensor output")
    chi = info.get("adequacy", {}).get("chi2_per_datum")
    ax.set_title(f"{title} · chi-square per datum {chi:.2f}" if chi is not None else title)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(loc="best", fontsize="small")
    return _save(fig, path, margins=True)


def plot_sensor_fit(path: Path, t, measured, fitted, names, title: str = "") -> Path:
    """Measured vs fitted over time, one panel per sensor: a DIC run's virtual stretch sensors (from
    the frames) and the same sensors on the full-field fit's deflection, with the RMS residual."""
    plt = _pyplot()
    measured, fitted = np.asarray(measured, dtype=float), np.asarray(fitted, dtype=float)
    p = measured.shape[1]
    cols = 2 if p > 1 else 1
    rows = -(-p // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.4 * cols / 1.4, 2.0 * rows + 0.6), squeeze=False, sharex=True)
    for j, ax in enumerate(axes.ravel()):
        if j >= p:
            ax.set_visible(False)
            continue
        rms = float(np.sqrt(np.nanmean((measured[:, j] - fitted[:, j]) ** 2)))
        ax.plot(t, fitted[:, j], color="C1", lw=1.6, label="fitted")
        ax.plot(t, measured[:, j], ".", color="k", ms=1.5, label="measured")  # on top: where they part shows
        ax.set_title(f"{names[j]} · RMS residual {rms:.2g}", fontsize="small")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="best", fontsize="small")
    for ax in axes[-1]:
        ax.set_xlabel("t (s)")
    if title:
        fig.suptitle(f"{title} · measured vs fitted", fontsize="medium")
    return _save(fig, path)
