"""Batch use of the joint EKF: one whole record through the filter (:meth:`JointEKF.run`)."""

from __future__ import annotations

import dataclasses
import logging
import time
from typing import TYPE_CHECKING

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.noise import JEKF_NOISE, noise_variance
from wingopt.estimation.result import IdentificationResult
from wingopt.measurements.series import Measurements

if TYPE_CHECKING:
    from wingopt.estimation.jekf.filter import JointEKF

__all__ = ["filter_record"]

log = logging.getLogger(__name__)


def filter_record(
    ekf: JointEKF, measurements: Measurements, setup: bool = True, progress: bool = False
) -> IdentificationResult:
    """Run ``ekf`` over a whole record (:meth:`JointEKF.run`); returns the posterior histories at every sample time.

    ``info`` holds: ``settings`` (dict), ``structure``, ``modes``, ``R`` (variances used),
    ``R_source``, ``initial_load_Pa``, ``initial_peak_m``, ``updates``, ``skipped`` (all-NaN
    samples: prediction only), ``innovations`` ``(N, p)`` (``y_k - h(x_k^-)``, NaN where
    missing), ``nis`` (per sample, NaN when skipped), ``mean_nis`` (per scalar measurement; ~1
    when the filter's statistics match the data), ``loglik`` (Gaussian prediction-error
    log-likelihood of the data), ``seconds_per_sample`` (wall) and ``cpu_seconds_per_sample``
    (process CPU time: less sensitive to a busy machine), ``sample_period``, ``build_s``.
    """
    if not isinstance(measurements, Measurements):
        raise InputError(f"measurements: expected Measurements, got {type(measurements).__name__}")
    names = tuple(measurements.sensor_names)
    if names != tuple(ekf.sensors.names):
        raise InputError(f"measurements.sensor_names = {names!r}: expected {tuple(ekf.sensors.names)!r}")
    if measurements.count == 0:
        raise InputError("measurements: no samples")
    R_source = "settings"
    if setup:
        R = ekf.settings.measurement_variance
        if R is None:
            R, R_source = noise_variance(measurements, ekf.model.problem.identification.noise_std, JEKF_NOISE)
        ekf.setup(measurement_variance=R, t0=float(measurements.t[0]))
    elif not ekf._ready:
        raise InputError("run(setup=False): call setup() first")
    else:
        R_source = "setup()"
    N = measurements.count
    states = np.empty((N, ekf.size))  # mapped to loads, deflections and lift after the loop (one product each)
    lift_std = np.empty(N)
    nis = np.empty(N)
    innov = np.empty((N, ekf.p))
    iterator = range(N)
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, desc="jekf", unit="sample", leave=False)
    t0, c0 = time.perf_counter(), time.process_time()
    for k in iterator:
        ekf.step(measurements.values[k], t=float(measurements.t[k]))
        states[k] = ekf.x
        lift_std[k] = ekf.lift_std
        nis[k] = ekf.last_nis
        innov[k] = ekf.last_innovation
    ekf._symmetrize()
    loads, defl, lift = ekf._histories(states)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    s = ekf.settings
    info = {
        "settings": dataclasses.asdict(s),
        "structure": s.structure,
        "modes": ekf.r,
        "R": ekf.R.tolist(),
        "R_source": R_source,
        "initial_load_Pa": ekf.prior.initial_load_value,
        "initial_peak_m": ekf.prior.initial_peak,
        "updates": ekf._updates,
        "skipped": ekf._skipped,
        "nis": nis,
        "innovations": innov,
        "mean_nis": ekf.nis_sum / max(ekf.innovation_count, 1),
        "loglik": ekf.loglik,
        "seconds_per_sample": wall / N,
        "cpu_seconds_per_sample": cpu / N,
        "sample_period": float(np.median(np.diff(measurements.t))) if N > 1 else ekf.dt,
        "build_s": ekf.build_seconds,
    }
    log.debug("jekf: %d samples in %.2f s (%.2f ms/sample), lambda %.3g", N, wall, 1e3 * wall / N, s.regularization)
    return IdentificationResult(
        method="jekf",
        t=measurements.t.copy(),
        load=loads,
        deflection=defl,
        lift=lift,
        lift_std=lift_std,
        regularization=float(s.regularization),
        wall_s=wall,
        info=info,
    )
