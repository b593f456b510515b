"""The realistic estimator's start-up: its modal model, the initial state's prior, the amplitude scan."""

from __future__ import annotations

import dataclasses
import functools
import logging

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.realistic.record_problem import RecordProblem
from wingopt.estimation.realistic.solver import levenberg_marquardt
from wingopt.membrane import bubble
from wingopt.membrane.modal import BergerModal, FvKModal, ModalMembrane

__all__ = ["initial_state_prior", "modal_model", "scan", "short_start", "SCAN_S", "SHORT_START_ITER"]

log = logging.getLogger(__name__)


def initial_state_prior(bm: ModalMembrane, problem, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """Prior mean and std of ``[q0, q0']``: the file's bubble when stated, else zero at the data's scale."""
    peak = problem.identification.initial_deflection
    md = bm.m
    omega = bm.omega()[:md]
    known = peak != 0
    if known:
        q = bm.to_modal(bm.model.project(bubble(problem.width, problem.height, peak)))[:md]
        amp = abs(q[0])
    else:
        q = np.zeros(md)
        smax = np.nanmax(np.abs(y))
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
    Q = short.trajectory(th).real
    costs = []
    for b in range(amps.size):
        pred = short.model.outputs(Q[:, b])
        r = ((short.y - pred) / short.sigma)[short.valid]
        costs.append(weight * float(r @ r))
    costs = np.array(costs) + amps**2
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
    the start-up, as the scan: not counted in ``max_total_iter``."""
    n = int(np.searchsorted(rp.t, rp.t[0] + SCAN_S, side="right"))
    if 2 * n > rp.t.size:
        return theta0
    short = dataclasses.replace(rp, t=rp.t[:n], y=rp.y[:n])
    fit = levenberg_marquardt(short, theta0, SHORT_START_ITER)
    log.debug("short start: %d iterations on %d samples, cost %.4g", fit.iterations, n, fit.cost)
    return fit.theta


class _Wing:
    """A membrane model as a cache key: what its modal model depends on (geometry, mesh, material,
    sensors), not the identification settings, so a re-read or recalibrated problem file hits."""

    def __init__(self, model) -> None:
        p = model.problem
        self.model, self.key = model, (p.width, p.height, p.nodes, p.material, p.sensors)

    def __hash__(self) -> int:
        return hash(self.key)

    def __eq__(self, other) -> bool:
        return isinstance(other, _Wing) and self.key == other.key


def modal_model(model, kind, modes, dt, substeps, stretch_gain, cubic_modes) -> ModalMembrane:
    """The estimator's modal model, built once per wing and settings: a lab's records of one wing
    share it (the FvK tensor of 30 cubic modes takes 1-1.5 s, more than a steady record's fit). The
    sample period and sub-steps are not part of the build (the modes and the tensor do not depend on
    them): records at 300 Hz and 1 kHz share one build, each with its own ``dt`` and ``substeps``."""
    if not (isinstance(substeps, (int, np.integer)) and substeps >= 1):
        raise InputError(f"substeps = {substeps!r}: expected an integer >= 1")
    if not (np.isfinite(dt) and dt > 0):
        raise InputError(f"dt = {dt!r}: expected a positive sample period (s)")
    bm = _modal_model(_Wing(model), kind, modes, stretch_gain, cubic_modes)
    return dataclasses.replace(bm, dt=float(dt), substeps=int(substeps))


@functools.lru_cache(maxsize=4)
def _modal_model(wing: _Wing, kind, modes, stretch_gain, cubic_modes) -> ModalMembrane:
    model = wing.model
    if kind == "fvk":
        return FvKModal.build(model, modes, cubic_modes=cubic_modes)
    return BergerModal.build(model, modes, stretch_gain=stretch_gain)
