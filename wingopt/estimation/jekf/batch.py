"""Batch use of the joint EKF: one whole record through the filter (:meth:`JointEKF.run`).

:class:`WholeRecord` is the filter's whole-record half, inherited by
:class:`~wingopt.estimation.jekf.filter.JointEKF`, whose step-able half (``setup`` / ``step``) it
drives; it names nothing of that module, so the two do not import each other.
"""

from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.core.noise import JEKF_NOISE, noise_variance
from wingopt.estimation.core.result import IdentificationResult
from wingopt.measurements.series import Measurements

__all__ = ["WholeRecord"]

log = logging.getLogger(__name__)


class WholeRecord:
    """The whole-record use of the joint EKF (:meth:`run`), inherited by :class:`JointEKF`."""

    def run(self, measurements: Measurements, setup: bool = True, progress: bool = False) -> IdentificationResult:
        """Filter a whole record; returns the posterior histories at every sample time.

        ``info`` holds: ``settings`` (dict), ``structure``, ``modes``, ``R`` (variances used),
        ``R_source``, ``initial_load_Pa``, ``initial_peak_m``, ``updates``, ``skipped`` (all-NaN
        samples: prediction only), ``innovations`` ``(N, p)`` (``y_k - h(x_k^-)``, NaN where
        missing), ``nis`` (per sample, NaN when skipped), ``mean_nis`` (per scalar measurement; ~1
        when the filter's statistics match the data), ``loglik`` (Gaussian prediction-error
        log-likelihood of the data), ``seconds_per_sample`` (wall) and ``cpu_seconds_per_sample``
        (process CPU time: less sensitive to a busy machine), ``sample_period``, ``build_s``.
        """
        self._check_record(measurements)
        R_source = self._start_record(measurements, setup)
        (loads, defl, lift, lift_std, nis, innov), wall, cpu = self._filter_samples(measurements, progress)
        s = self.settings
        N = measurements.count
        info = self._record_info(measurements, R_source, nis, innov, wall, cpu)
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

    def _check_record(self, measurements: Measurements) -> None:
        """Refuse a record that is not this filter's sensors' (or has no samples)."""
        if not isinstance(measurements, Measurements):
            raise InputError(f"measurements: expected Measurements, got {type(measurements).__name__}")
        names = tuple(measurements.sensor_names)
        if names != tuple(self.sensors.names):
            raise InputError(f"measurements.sensor_names = {names!r}: expected {tuple(self.sensors.names)!r}")
        if measurements.count == 0:
            raise InputError("measurements: no samples")

    def _start_record(self, measurements: Measurements, setup: bool) -> str:
        """Set the filter up at the record's first sample (``R`` from the data when the settings
        say ``None``), or check it was; returns where ``R`` came from."""
        if not setup:
            if not self._ready:
                raise InputError("run(setup=False): call setup() first")
            return "setup()"
        R, R_source = self.settings.measurement_variance, "settings"
        if R is None:
            R, R_source = noise_variance(measurements, self.settings.declaration.noise_std, JEKF_NOISE)
        self.setup(measurement_variance=R, t0=float(measurements.t[0]))
        return R_source

    def _filter_samples(self, measurements: Measurements, progress: bool):
        """Step through every sample: the histories ``(loads, deflections, lift, lift_std, nis,
        innovations)``, then the wall and CPU seconds it took."""
        N = measurements.count
        states = np.empty((N, self.size))  # mapped to loads, deflections and lift after the loop (one product each)
        lift_std = np.empty(N)
        nis = np.empty(N)
        innov = np.empty((N, self.p))
        iterator = range(N)
        if progress:
            from tqdm import tqdm

            iterator = tqdm(iterator, desc="jekf", unit="sample", leave=False)
        t0, c0 = time.perf_counter(), time.process_time()
        for k in iterator:
            self.step(measurements.values[k], t=float(measurements.t[k]))
            states[k] = self.x
            lift_std[k] = self.lift_std
            nis[k] = self.last_nis
            innov[k] = self.last_innovation
        self._symmetrize()
        loads, defl, lift = self._histories(states)
        return (loads, defl, lift, lift_std, nis, innov), time.perf_counter() - t0, time.process_time() - c0

    def _record_info(self, measurements: Measurements, R_source: str, nis, innov, wall: float, cpu: float) -> dict:
        """The run's ``info`` (see :meth:`run`)."""
        s, N = self.settings, measurements.count
        return {
            "settings": dataclasses.asdict(s),
            "structure": s.structure,
            "modes": self.r,
            "R": self.R.tolist(),
            "R_source": R_source,
            "initial_load_Pa": self.prior.initial_load_value,
            "initial_peak_m": self.prior.initial_peak,
            "updates": self._updates,
            "skipped": self._skipped,
            "nis": nis,
            "innovations": innov,
            "mean_nis": self.nis_sum / max(self.innovation_count, 1),
            "loglik": self.loglik,
            "seconds_per_sample": wall / N,
            "cpu_seconds_per_sample": cpu / N,
            "sample_period": float(np.median(np.diff(measurements.t))) if N > 1 else self.dt,
            "build_s": self.build_seconds,
        }
