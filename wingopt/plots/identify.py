"""Figures of a load identification: pressure field, lift history with its band, error histories."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wingopt.estimation.registry import FRAME_METHODS
from wingopt.plots import pyplot as _pyplot
from wingopt.plots import save as _save

__all__ = ["plot_load_field", "plot_lift", "plot_errors", "plot_overlay", "error_histories", "plot_identification"]


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
    return _save(fig, path, margins=True)


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
    reported: tuple[float, float | None] | None = None,
):
    """Lift history with its 1-sigma band and the true lift when known; returns the figure.

    ``ax``: draw into this axes (nothing is written; ``path`` may be ``None``).

    ``reported``: the reported lift and its 1-sigma ``(mean, std)`` (a steady record's mean), drawn as
    a line and a band across the record and named in the legend.

    ``first_window_s`` shades the first MHE window, whose samples carry the first window's
    (smoothed) estimate, available only at the window's end.
    """
    fig, ax, own = _axes(ax)
    _first_window(ax, first_window_s)
    ax.plot(t, lift, color="C0", label="estimate")
    if std is not None and np.any(np.isfinite(std)):
        ax.fill_between(t, lift - std, lift + std, color="C0", alpha=0.25, label="1-sigma band")
    if reported is not None and reported[0] is not None and np.isfinite(reported[0]):
        mean, sd = reported
        text = f"reported {mean:.4g} N" + ("" if sd is None else f" ± {sd:.2g} N (1 sd)")
        ax.axhline(mean, color="C3", lw=1.5, label=text, zorder=3)
        if sd is not None and np.isfinite(sd):
            ax.axhspan(mean - sd, mean + sd, color="C3", alpha=0.15, lw=0)
    if truth is not None:
        ax.axhline(truth, color="k", ls="--", lw=1, label="truth")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("lift (N)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    if title:
        ax.set_title(title)
    return _save(fig, path if own else None, margins=True)


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
    return _save(fig, path if own else None, margins=True)


def plot_overlay(
    path: Path | None,
    curves,
    truth_t: np.ndarray | None = None,
    truth_lift: np.ndarray | float | None = None,
    title: str = "",
    ax=None,
):
    """Lift histories of several estimators on one axes, each with its 1-sigma band, and the truth.

    Parameters
    ----------
    path : Path or None
        PNG to write (nothing when ``ax`` is given).
    curves : sequence of (label, t, lift, std)
        One per estimator (``std`` ``None`` or all-NaN: no band), e.g. the MHE and the JEKF; the
        first is drawn on top.
    truth_t, truth_lift : array or float, optional
        The true lift history (``truth_lift`` a number: a constant line).
    title : str

    The vertical range covers the curves, bands and truth after the first tenth of the record (a
    filter's wide start-up band would flatten everything else); what lies beyond is clipped.
    ax : matplotlib axes, optional

    Returns
    -------
    Figure
    """
    fig, ax, own = _axes(ax)
    seen = []  # values that set the vertical range (a filter's start-up band would flatten the rest)
    for i, (label, t, lift, std) in enumerate(curves):
        t, lift = np.asarray(t, dtype=float), np.asarray(lift, dtype=float)
        color = f"C{i}"
        band = std is not None and np.any(np.isfinite(np.asarray(std, dtype=float)))
        top = 2.5 + len(curves) - i  # the first curve (the MHE) drawn over the others
        ax.plot(t, lift, color=color, lw=1.3, label=f"{label} (1-sigma band)" if band else label, zorder=top)
        later = t >= t[0] + 0.1 * (t[-1] - t[0]) if t.size > 1 else np.ones(t.size, bool)
        seen.append(lift[later])
        if band:
            std = np.asarray(std, dtype=float)
            ax.fill_between(t, lift - std, lift + std, color=color, alpha=0.2, lw=0, zorder=1)
            seen += [(lift - std)[later], (lift + std)[later]]
    if truth_lift is not None:
        if truth_t is None or np.ndim(truth_lift) == 0:
            ax.axhline(float(np.ravel(truth_lift)[-1]), color="k", ls="--", lw=1, label="truth")
        else:
            ax.plot(truth_t, truth_lift, color="k", ls="--", lw=1, label="truth")
        seen.append(np.ravel(np.asarray(truth_lift, dtype=float)))
    vals = np.concatenate(seen) if seen else np.array([])
    vals = vals[np.isfinite(vals)]
    if vals.size:
        lo, hi = np.percentile(vals, [1, 99])
        pad = 0.15 * (hi - lo) or 0.1 * max(abs(lo), abs(hi), 1e-6)
        ax.set_ylim(lo - pad, hi + pad)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("lift (N)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    if title:
        ax.set_title(title)
    return _save(fig, path if own else None, margins=True)


def _basis_space(space):
    """The :class:`~wingopt.fe.space.TensorSpace` behind ``space`` (a load space carries one)."""
    space = getattr(space, "space", space)
    return space if hasattr(space, "basis_matrix") else None


def error_histories(case, result, model, index: np.ndarray, order: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Relative L2 errors of the estimated load and deflection at the samples ``index`` (for :func:`plot_errors`).

    The same numbers as ``case.load_error(load_field(result, model, k))`` and
    ``case.deflection_error(model.field(result.deflection[k]), kt)`` (``kt``: the truth's sample
    nearest ``result.t[k]``; the load against the truth's final load, as
    :meth:`~wingopt.membrane.TruthRecord.load_error`), but each mesh's basis is evaluated at the
    truth mesh's quadrature points once for all samples, not twice per sample (the error history
    of a 41-point plot cost ~170 basis evaluations, 13–20 s of CPU, before).

    Parameters
    ----------
    case : TruthRecord
        The simulated truth.
    result : IdentificationResult
        Load coefficients ``result.load`` in ``result.load_space`` (default the model's space) and
        deflections ``result.deflection`` in the model's space, at times ``result.t``.
    model : MembraneModel
        The estimator's model.
    index : array of int
        Samples of ``result`` to evaluate.
    order : int
        Gauss points per direction and cell (8, as the truth's error metrics).

    Returns
    -------
    load_error, deflection_error : ndarray
        One value per entry of ``index``.
    """
    index = np.asarray(index, dtype=int)
    truth_space = case.truth_model.space
    load_space = _basis_space(result.load_space if result.load_space is not None else model.space)
    defl_space = _basis_space(model.space)
    if load_space is None or defl_space is None:
        raise TypeError("error_histories: the load and deflection spaces must be tensor spline spaces")
    x, y, w = truth_space.cells().quadrature(order)
    x, y, w = x.ravel(), y.ravel(), w.ravel()
    t_case = np.asarray(case.trajectory.t)
    kt = np.array([int(np.argmin(np.abs(t_case - result.t[k]))) for k in index], dtype=int)

    def rel(truth_vals: np.ndarray, est_vals: np.ndarray) -> np.ndarray:
        num = (w[:, None] * (truth_vals - est_vals) ** 2).sum(axis=0)
        den = (w[:, None] * truth_vals**2).sum(axis=0)
        return np.sqrt(num / den)

    p_true = np.asarray(case.load(x, y), dtype=float)[:, None]
    p_est = load_space.basis_matrix(x, y) @ np.asarray(result.load, dtype=float)[index].T
    w_true = truth_space.basis_matrix(x, y) @ np.asarray(case.trajectory.z, dtype=float)[kt].T
    w_est = defl_space.basis_matrix(x, y) @ np.asarray(result.deflection, dtype=float)[index].T
    return rel(p_true, p_est), rel(w_true, w_est)


def _sensor_fit(run):
    """``(t, measured, fitted)``: the record's sensor values and the sensors on the fitted deflection at
    the same samples (``None`` when the result has no deflection history on the record's times)."""
    r, m = run.result, run.measurements
    z = np.asarray(r.deflection, dtype=float)
    if z.ndim != 2 or z.shape[1] != run.model.n or len(r.t) != len(m.t) or not np.allclose(r.t, m.t):
        return None
    fitted = np.stack([np.einsum("ki,ki->k", z, (C @ z.T).T) for C in run.model.sensors.matrices], axis=1)
    return r.t, m.values, fitted


def plot_identification(tmp: Path, run, X, Y, P, S=None, title: str | None = None) -> dict:
    """The figures of an identification run (:class:`~wingopt.workflows.identify.IdentifyRun`) into
    ``tmp``: the field behind the reported lift on the grid ``X, Y`` (``P``, Pa) with its band ``S``
    beside it, the lift history with the reported lift, the misfit and, with a truth, the error
    histories. Returns ``{file name: caption}`` of the figures written."""
    from wingopt.plots.field import plot_field_band

    result, case = run.result, run.case
    title = title or f"{run.protocol.get('load_case', 'data')} · {run.method}"
    lift, band = result.reported_lift
    written = {}
    first = None
    if "window" in result.info:  # a windowed estimator (the MHE): mark its first window's end
        first = float(result.t[min(result.info["window"], result.t.size) - 1] - result.t[0])
    truth = None if case is None else case.load(X, Y)
    plot_field_band(
        tmp / "load_field.png",
        X,
        Y,
        P,
        S,
        lift=lift,
        lift_std=band,
        sensors=run.problem.sensors,
        truth=truth,
        title=title,
    )
    written["load_field.png"] = "the field behind the reported lift (load.csv), its 1-sigma band, the sensors"
    true_lift = None if case is None else case.true_lift
    plot_lift(tmp / "lift.png", result.t, result.lift, result.lift_std, true_lift, title, first, reported=(lift, band))
    written["lift.png"] = "the lift history (lift.csv) with its band, and the reported lift ± its band"
    if "segments_t_s" in result.info.get("adequacy", {}):
        from wingopt.plots.misfit import plot_misfit

        plot_misfit(tmp / "misfit.png", result.info["adequacy"], title)
        written["misfit.png"] = "chi-square per datum per segment of the record"
    elif "sensor_fit" in result.info:  # a steady record: its data are the sensors' means
        from wingopt.plots.misfit import plot_sensor_means

        plot_sensor_means(tmp / "misfit.png", result.info, run.model.problem.sensor_names, title)
        written["misfit.png"] = "measured vs fitted: each sensor's mean and the static fit"
    elif result.method in FRAME_METHODS and _sensor_fit(run) is not None:  # DIC: the frames' virtual sensors
        from wingopt.plots.misfit import plot_sensor_fit

        t, measured, fitted = _sensor_fit(run)
        plot_sensor_fit(tmp / "misfit.png", t, measured, fitted, run.model.problem.sensor_names, title)
        written["misfit.png"] = "measured vs fitted: the frames' virtual sensors and the same sensors on the fit"
    if case is not None:
        idx = np.unique(np.linspace(0, result.t.size - 1, 41).astype(int))
        le, de = error_histories(case, result, run.model, idx)
        plot_errors(tmp / "errors.png", result.t[idx], le, de, title, first)
        written["errors.png"] = "relative L2 errors of the load and the deflection against the truth"
    return written
