"""Sampled sensor series, simulated or measured: :class:`Measurements`."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError

__all__ = ["Measurements"]


def _real(name: str, value) -> np.ndarray:
    try:
        arr = np.asarray(value)
    except Exception:  # noqa: BLE001 - ragged input: the caller's mistake
        arr = None
    if arr is None or arr.dtype.kind not in "biuf":
        raise InputError(f"measurements: {name} of {type(value).__name__}: expected real numbers")
    return arr.astype(float)


@dataclass(frozen=True, eq=False)
class Measurements:
    """Stretch-sensor time series.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times (s), strictly increasing.
    values : ndarray, shape (N, p)
        Sensor outputs; NaN marks a missing sample (skipped by estimators, never invented).
    sensor_names : tuple of str
        Column names, in the order of the problem's sensors.
    noise_std : ndarray, shape (p,), optional
        Known noise standard deviation per sensor; ``None`` when it must be estimated.
    source : str
        Where the data came from (a file name, or ``"simulated L1 1% seed 0"``).
    simulated : bool
        The package simulated these values (:mod:`wingopt.membrane.truth`): they are in its own
        units, so the unit and scale hints of :mod:`wingopt.estimation.core.sanity` do not apply.
    clock : dict, optional
        The stamps were jittered and read as a uniform clock: its fitted step and largest deviation
        (:meth:`~wingopt.measurements.clock.Clock.as_dict`); the data checks report it.
    """

    t: np.ndarray
    values: np.ndarray
    sensor_names: tuple[str, ...]
    noise_std: np.ndarray | None = None
    source: str = ""
    simulated: bool = False
    clock: dict | None = None

    def __post_init__(self) -> None:
        t, v = _real("t", self.t), _real("values", self.values)
        names = self.sensor_names
        if not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names):
            raise InputError(f"sensor_names = {self.sensor_names!r}: expected a sequence of names, e.g. ('S1', 'S2')")
        if not np.all(np.isfinite(t)):
            raise InputError("t: holds NaN or inf: every sample needs a time")
        if t.ndim != 1 or v.ndim != 2 or v.shape[0] != t.size:
            raise InputError(f"measurements: t has shape {t.shape} and values {v.shape}, expected (N,) and (N, p)")
        if v.shape[1] != len(self.sensor_names):
            raise InputError(f"measurements: {v.shape[1]} columns for {len(self.sensor_names)} sensor names")
        if t.size and np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0)) + 1
            raise InputError(f"t[{k}] = {float(t[k])!r} after {float(t[k - 1])!r}: expected strictly increasing times")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "values", v)

    @property
    def count(self) -> int:
        return self.t.size

    def since(self, k: int) -> Measurements:
        """The record from sample ``k`` on (a pre-trigger left out: :mod:`wingopt.estimation.core.onset`)."""
        return dataclasses.replace(self, t=self.t[k:], values=self.values[k:])

    @property
    def missing(self) -> np.ndarray:
        """Boolean ``(N,)``: rows with at least one missing value."""
        return np.isnan(self.values).any(axis=1)
