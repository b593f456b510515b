"""Sensor noise level from the data alone: one estimator, two documented settings.

Differencing a densely sampled record removes its smooth part (the membrane's modes are sampled
many times per period) and leaves the noise: for white noise of std ``sigma`` the ``k``-th
differences have variance ``C(2k, k) sigma^2`` (6 for second, 20 for third differences). A robust
statistic ignores the few samples of a start-up transient or a gust:

* :data:`MHE_NOISE` — second differences over the last 60 % of the record (after the start-up
  transient), outliers beyond 5 robust standard deviations dropped, then the plain standard
  deviation (about 3 % accuracy from 600 samples);
* :data:`JEKF_NOISE` — third differences over the whole record, ``1.4826 MAD`` (median absolute
  deviation); on the simulated protocol it overestimates by ~3 % (1 % noise) and ~2 % (5 %).

Both were measured on the studies of ``docs/estimation_comparison.md``; they stay distinct
settings of this one estimator so that those tables are reproduced exactly. Missing samples (NaN)
are skipped: a difference that touches one is dropped (no differencing across a gap).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError

__all__ = ["NoiseRule", "MHE_NOISE", "JEKF_NOISE", "estimate_noise_std", "noise_variance", "resolve_noise_std"]

_MIN_DIFFERENCES = 10
_VARIANCE_FLOOR = 1e-6  # relative floor of the noise std (noise-free data would give R = 0)


@dataclass(frozen=True)
class NoiseRule:
    """How :func:`estimate_noise_std` reads the noise off a record.

    Parameters
    ----------
    order : int
        Order ``k`` of the differences.
    tail : float
        Fraction of the record (its end) used, in ``(0, 1]``.
    statistic : {"trimmed_std", "mad"}
        ``"trimmed_std"``: standard deviation after dropping differences beyond 5 robust standard
        deviations; ``"mad"``: ``1.4826`` times the median absolute deviation.
    """

    order: int = 2
    tail: float = 1.0
    statistic: str = "trimmed_std"

    def __post_init__(self) -> None:
        if int(self.order) != self.order or self.order < 1:
            raise InputError(f"order = {self.order!r}: expected a positive integer")
        if not 0.0 < self.tail <= 1.0:
            raise InputError(f"tail = {self.tail!r}: expected a fraction of the record in (0, 1]")
        if self.statistic not in ("trimmed_std", "mad"):
            raise InputError(f"statistic = {self.statistic!r}: expected trimmed_std or mad")


MHE_NOISE = NoiseRule(order=2, tail=0.6, statistic="trimmed_std")
JEKF_NOISE = NoiseRule(order=3, tail=1.0, statistic="mad")


def estimate_noise_std(
    values: np.ndarray,
    rule: NoiseRule = MHE_NOISE,
    names: Sequence[str] | None = None,
    difference_gain: float | None = None,
) -> np.ndarray:
    """Per-sensor noise standard deviation estimated from the data alone.

    Parameters
    ----------
    values : ndarray (samples, sensors)
        Uniformly sampled record; NaN = missing.
    rule : NoiseRule
        Differences, tail and statistic (:data:`MHE_NOISE` by default).
    names : sequence of str, optional
        Sensor names for the error messages.
    difference_gain : float, optional
        The differences' variance over the noise's: ``C(2k, k)`` for white noise (default); a DAQ's
        filter colours the noise (:meth:`~wingopt.measurements.acquisition.Acquisition.difference_gain`).

    Returns
    -------
    ndarray (sensors,)
        Noise std per sensor (may be 0 for noise-free or quantised data: the caller decides).
    """
    v = np.asarray(values, dtype=float)
    if v.ndim != 2:
        raise InputError(f"values: shape {v.shape}, expected (samples, sensors)")
    k = rule.order
    start = int(v.shape[0] * (1 - rule.tail))
    norm = math.sqrt(math.comb(2 * k, k) if difference_gain is None else difference_gain)
    out = np.empty(v.shape[1])
    for i in range(v.shape[1]):
        d = np.diff(v[start:, i], k)
        d = d[np.isfinite(d)]
        if d.size < _MIN_DIFFERENCES:
            name = names[i] if names is not None else f"column {i + 1}"
            raise InputError(
                f"sensor {name}: {d.size} usable differences, need {_MIN_DIFFERENCES} to estimate its noise; "
                "give noise_std or a longer record"
            )
        med = np.median(d)
        mad = 1.4826 * np.median(np.abs(d - med))
        if rule.statistic == "mad":
            out[i] = mad / norm
        else:
            keep = d[np.abs(d - med) <= 5 * mad] if mad > 0 else d
            out[i] = np.std(keep) / norm
    return out


def resolve_noise_std(
    values: np.ndarray,
    names: Sequence[str],
    given=None,
    measured=None,
    problem=None,
    rule: NoiseRule = MHE_NOISE,
    allow_zero: bool = False,
    acquisition=None,
    fs: float | None = None,
) -> tuple[np.ndarray, str]:
    """The noise std every estimator uses, and where it came from: the one precedence rule.

    ``given`` (an argument, ``--noise-std``) > ``measured`` (what the measurements carry, e.g. a
    simulation's) > ``problem`` (the problem file's ``identification.noise_std``) > estimated from
    ``values`` with ``rule``. A value that is not positive and finite is refused in one line
    (an estimate of zero, noise-free or quantised data, too, unless ``allow_zero``). A declared
    ``acquisition`` (the record sampled at ``fs``, Hz) sets how the differences see the noise.
    """
    p = np.shape(values)[1]
    for value, source in ((given, "argument"), (measured, "measurements"), (problem, "problem file")):
        if value is not None:
            sigma = np.broadcast_to(np.asarray(value, dtype=float), (p,)).copy()
            if not np.all(np.isfinite(sigma) & (sigma > 0)):
                raise InputError(f"noise_std = {sigma.tolist()} ({source}): expected positive finite values")
            return sigma, source
    gain = None if acquisition is None else acquisition.difference_gain(rule.order, fs)
    sigma = estimate_noise_std(values, rule, names, gain)
    if np.any(sigma <= 0) and not allow_zero:
        raise InputError("noise estimate: a sensor looks noise-free (constant or quantised); give noise_std")
    return sigma, "estimated from the data"


def noise_variance(measurements, problem_noise_std=None, rule: NoiseRule = JEKF_NOISE) -> tuple[np.ndarray, str]:
    """Measurement variances ``R_i`` for a record, and where they came from.

    The precedence of :func:`resolve_noise_std` (measurements, problem file, estimate); a floor
    of ``1e-6 max_t |y_i|`` keeps ``R > 0`` on noise-free data.
    """
    values, names = measurements.values, measurements.sensor_names
    std, source = resolve_noise_std(
        values, names, measured=measurements.noise_std, problem=problem_noise_std, rule=rule, allow_zero=True
    )
    if source == "estimated from the data":
        source = f"estimated (order-{rule.order} differences, {rule.statistic})"
    scale = np.nanmax(np.abs(values), axis=0)
    floor = _VARIANCE_FLOOR * np.where(np.isfinite(scale) & (scale > 0), scale, 1.0)
    if np.any(std < floor):
        source += " (floored)"
    return np.maximum(std, floor) ** 2, source
