"""The record a moving-horizon run works on: checked, uniformly sampled, weighted.

Missing samples (NaN) get weight 0 and are never invented; the noise level is the caller's, the
measurements', the problem's, or estimated from the data (:func:`~wingopt.estimation.core.noise.resolve_noise_std`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.core.noise import resolve_noise_std
from wingopt.measurements.series import Measurements

__all__ = ["Record", "weighted_record"]


@dataclass(frozen=True, eq=False)
class Record:
    """A uniformly sampled record with its weights.

    Attributes
    ----------
    t : ndarray ``(K,)``
        Sample times (s).
    y, w : ndarray ``(K, p)``
        Outputs (0 where missing) and weights ``1 / sigma^2`` (0 where missing).
    dt : float
        Sample time (s).
    noise_std : ndarray ``(p,)``
        Noise std per sensor, and ``noise_source`` where it came from.
    missing_rows : int
        Samples with at least one missing output.
    peak : float
        Largest absolute output (the estimator's scaling).
    """

    t: np.ndarray
    y: np.ndarray
    w: np.ndarray
    dt: float
    noise_std: np.ndarray
    noise_source: str
    missing_rows: int
    peak: float


def weighted_record(
    measurements: Measurements,
    sensor_names: tuple[str, ...],
    noise_std: np.ndarray | float | None,
    problem_noise_std: np.ndarray | float | None,
) -> Record:
    """Check ``measurements`` against the problem's sensors and weight them.

    Parameters
    ----------
    measurements : Measurements
        Uniformly sampled; NaN entries are missing samples.
    sensor_names : tuple of str
        The problem's sensors (the columns must be these, in this order).
    noise_std : float or array, optional
        The caller's sensor noise std.
    problem_noise_std : float or array, optional
        The problem's ``identification.noise_std`` (used after the caller's and the measurements').

    Returns
    -------
    Record

    Raises
    ------
    InputError
        Other sensors, fewer than 2 samples, irregular sampling, or every sample missing.
    """
    if not isinstance(measurements, Measurements):
        raise InputError(f"measurements = {type(measurements).__name__}: expected a Measurements")
    meas = measurements
    if tuple(meas.sensor_names) != tuple(sensor_names):
        raise InputError(
            f"measurements: sensors {list(meas.sensor_names)} do not match the problem's {list(sensor_names)}"
        )
    if meas.count < 2:
        raise InputError("measurements: need at least 2 samples")
    dt = float(np.median(np.diff(meas.t)))
    if np.max(np.abs(np.diff(meas.t) - dt)) > 1e-6 * dt:
        raise InputError("measurements: irregular sampling; resample to a uniform time step first")
    y = np.array(meas.values, dtype=float)
    missing = ~np.isfinite(y)
    missing_rows = int(np.count_nonzero(missing.any(axis=1)))
    if missing.all():
        raise InputError("measurements: every sample is missing")
    sigma, source = resolve_noise_std(y, sensor_names, noise_std, meas.noise_std, problem_noise_std)
    w = np.where(missing, 0.0, 1.0 / sigma**2)
    peak = float(np.nanmax(np.abs(y)))
    return Record(meas.t, np.where(missing, 0.0, y), w, dt, sigma, source, missing_rows, peak)
