"""The realistic estimator's start-up: its modal model, the initial state's prior, the amplitude scan."""

from __future__ import annotations

import dataclasses
import logging

import numpy as np

from wingopt.estimation.core.record_fit import levenberg_marquardt
from wingopt.estimation.core.record_problem import RecordProblem
from wingopt.estimation.declaration import declaration_of
from wingopt.measurements.analog_filter import CausalFilter
from wingopt.measurements.decimation_filter import DecimationFilter
from wingopt.membrane import bubble
from wingopt.membrane.forward import ModalMembrane, modal_model

__all__ = ["initial_state_prior", "modal_model", "record_filter", "scan", "short_start", "SCAN_S", "SHORT_START_ITER"]

log = logging.getLogger(__name__)


def record_filter(problem) -> CausalFilter | DecimationFilter | None:
    """The problem's declared DAQ filter for the record fits' predictions, run on the outputs at the
    integrator's sub-steps: an analog one causally (:class:`~wingopt.measurements.analog_filter.
    CausalFilter`: a release rings in modes above the Nyquist frequency that the filter attenuates;
    read off the samples, L1 from the bubble through a Butterworth at fs/3 came out +19.9 % ± 3.9 N,
    run causally +0.1 % ± 0.25 N), a digital one as its response on that grid
    (:class:`~wingopt.measurements.decimation_filter.DecimationFilter`: it removes those modes; its
    delay where the time stamps keep it); ``None``: none declared, or point sampling."""
    acquisition = problem.acquisition
    return CausalFilter.of(acquisition) or DecimationFilter.of(acquisition)


def initial_state_prior(
    bm: ModalMembrane, problem, y: np.ndarray, initial_deflection: float | None = None
) -> tuple[np.ndarray, np.ndarray, bool]:
    """Prior mean and std of ``[q0, q0']``: the bubble of peak ``initial_deflection`` (m) when
    stated, else zero at the data's scale. ``initial_deflection``: the declaration's (the fit's
    ``settings.declaration``); ``None``: the problem's own ``[identification]``."""
    peak = declaration_of(problem).initial_deflection if initial_deflection is None else initial_deflection
    md = bm.m
    omega = bm.omega()[:md]
    known = peak != 0
    if known:
        q = bm.to_modal(bm.model.project(bubble(problem.width, problem.height, peak)))[:md]
        amp = abs(q[0])
    else:
        q = np.zeros(md)
        smax = np.nanmax(np.abs(y)) if np.isfinite(y).any() else 1.0  # no sample yet: any scale
        amp = float(np.sqrt(smax / np.max(np.abs(bm.sensor_matrices[:, 0, 0]))))
    sq = np.maximum(np.abs(q), amp * omega[0] / omega)
    sv = amp * omega[0] * np.ones(md)
    return np.concatenate([q, np.zeros(md)]), np.concatenate([sq, sv]), known


SCAN_S = 0.3
"""Seconds of the record the start-up scan simulates: the bubble's transient and the steady level,
all a ranking of load amplitudes needs (the fit then uses every sample). The scan was 15 % of a
1 s record's estimation; the chosen start was the same on every record of the robustness set."""


def scan(rp: RecordProblem, sign_pref: float) -> np.ndarray:
    """Best start on an amplitude grid along the smoothest shape (both signs), one batch run on the
    record's first ``SCAN_S`` seconds (its data cost scaled to the whole record's)."""
    grid = np.array([0.1, 0.2, 0.35, 0.5, 0.7, 1.0, 1.4, 2.0, 3.0])
    amps = np.concatenate([grid, -grid])
    th = np.zeros((amps.size, rp.dim))
    th[:, rp.slices["c"].start] = amps
    n = int(np.searchsorted(rp.t, rp.t[0] + SCAN_S, side="right"))
    short = rp if n >= rp.t.size - 1 else dataclasses.replace(rp, t=rp.t[:n], y=rp.y[:n])
    weight = rp.n_data / max(short.n_data, 1)
    # the candidates ranked on the record as the DAQ hands it over (its filter, if one is declared)
    r = np.where(short.valid[:, None], (short.y[:, None] - short.outputs(th)) / short.sigma, 0.0)
    costs = weight * np.sum(r**2, axis=(0, 2)) + amps**2
    costs[~np.isfinite(costs)] = np.inf  # a start the explicit integrator cannot follow (FvK at 3 prior std)
    best = int(np.argmin(costs))
    log.debug("scan: best amplitude %+.2f prior std (cost %.4g)", amps[best], costs[best])
    return th[best]


SHORT_START_ITER = 15
"""Levenberg–Marquardt iterations of :func:`short_start` at most."""


def short_start(rp: RecordProblem, theta0: np.ndarray) -> np.ndarray:
    """A start for the whole record's fit: ``theta0`` refined by a fit of the record's first
    ``SCAN_S`` seconds (at most ``SHORT_START_ITER`` iterations; the transient there holds the
    tension, the load and the initial state). Its iterations cost a fraction of the whole
    record's, and the whole fit then starts near its optimum (L1 on FvK truth, 1 s: 18 whole-record
    iterations from the scan). Records shorter than twice ``SCAN_S`` start from ``theta0``. Part of
    the start-up, as the scan: not counted in ``max_total_iter``.

    A problem with a gust amplitude has its knots over its own samples, so the short record has
    fewer: ``theta0``'s amplitude is read at the short record's knots, and the fitted one is
    written back on the whole record's knots inside the short window (``theta0``'s beyond it). The
    frame prior's fit of a gust record came here with the whole record's knots (153 unknowns for
    the short record's 83: "matmul ... size 153 is different from 83", L2 on FvK truth, no
    initial shape declared).
    """
    n = int(np.searchsorted(rp.t, rp.t[0] + SCAN_S, side="right"))
    if 2 * n > rp.t.size:
        return theta0
    short = dataclasses.replace(rp, t=rp.t[:n], y=rp.y[:n])
    fit = levenberg_marquardt(short, _moved(rp, theta0, short), SHORT_START_ITER)
    log.debug("short start: %d iterations on %d samples, cost %.4g", fit.iterations, n, fit.cost)
    return _moved(short, fit.theta, rp, theta0)


def _moved(src: RecordProblem, theta: np.ndarray, dst: RecordProblem, base: np.ndarray | None = None) -> np.ndarray:
    """``theta`` of ``src`` as unknowns of ``dst`` (the same record's problem on other samples): the
    state, load and parameters as they are, the gust amplitude interpolated onto ``dst``'s knots
    (piecewise linear, as it is); ``dst``'s knots beyond ``src``'s samples keep ``base``'s values."""
    if src.gust is None:
        return np.array(theta, dtype=float)
    out = np.zeros(dst.dim) if base is None else np.array(base, dtype=float)
    for name in ("x0", "c", "par"):
        out[dst.slices[name]] = theta[src.slices[name]]
    ks, kd = src.gust.knots(src.t), dst.gust.knots(dst.t)
    inside = kd <= ks[-1] + 1e-9 * (ks[-1] - ks[0])
    g = out[dst.slices["g"]]
    g[inside] = np.interp(kd[inside], ks, theta[src.slices["g"]])
    out[dst.slices["g"]] = g
    return out
