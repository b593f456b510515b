"""From a DAQ file's columns to the problem's stretch series: :class:`ChannelMap`.

A data-acquisition system writes its own column names (``time_s,ch1,ch2,ch3,ch4``) in its own
units (millivolts). A channel map says which column is the time (and its unit), which column
holds each sensor, and each sensor's calibration::

    stretch = gain * (raw - offset)

``gain`` is the stretch per raw unit (e.g. 1e-5 per mV) and ``offset`` the raw reading at zero
stretch (the bridge's zero, e.g. 250 mV), both per sensor. This is the DAQ's calibration, not the
sensor's model gain ``alpha`` of ``[[sensors]] gain``. Sensors not named keep their own name as
column, gain 1 and offset 0: the identity map reads the documented format (``t`` + one column
per sensor, dimensionless stretch) unchanged.

The map is declared in a problem file's ``[measurements]`` table (:mod:`wingopt.problem.membrane`)
or on the command line (``--columns S1=ch1,... --gain S1=1e-5,... --offset S1=250,...``, which
override the file key by key), and applied in one place, :meth:`ChannelMap.convert`, by the batch
reader (:func:`~wingopt.measurements.csv_file.read_measurements`) and the streaming parser
(:class:`~wingopt.measurements.csv_stream.CsvRowParser`) alike; :meth:`ChannelMap.as_dict` is
what a run records in its ``summary.json``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from wingopt.errors import InputError

__all__ = ["ChannelMap", "TIME_UNITS", "CONVENTION", "ALL"]

TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6}
"""Units of the time column: seconds per unit."""

CONVENTION = "stretch = gain * (raw - offset)"
"""How a raw reading becomes a stretch (recorded with the map)."""

ALL = "*"
"""Key of a gain or offset that applies to every sensor not named (``--gain 1e-5``, ``gain = 1e-5``)."""


def _pairs(value, what: str) -> tuple[tuple[str, object], ...]:
    if value is None:
        return ()
    if isinstance(value, Mapping):
        items = list(value.items())
    elif isinstance(value, (tuple, list)) and all(isinstance(p, (tuple, list)) and len(p) == 2 for p in value):
        items = [tuple(p) for p in value]
    else:
        raise InputError(f"{what} = {value!r}: expected a mapping of sensor name to value, e.g. {{'S1': ...}}")
    for k, _ in items:
        if not isinstance(k, str) or not k:
            raise InputError(f"{what}: key {k!r}: expected a sensor name")
    return tuple(items)


@dataclass(frozen=True)
class ChannelMap:
    """Which CSV column is the time and each sensor, and each sensor's gain and offset.

    Parameters
    ----------
    time : str
        The time column (default ``"t"``).
    time_unit : {"s", "ms", "us"}
        Unit of the time column.
    columns : mapping of str to str
        Sensor name -> CSV column (sensors not named: their own name).
    gain : mapping of str to float
        Sensor name -> stretch per raw unit (not named: 1; key ``"*"``: every sensor not named).
    offset : mapping of str to float
        Sensor name -> raw reading at zero stretch (not named: 0; key ``"*"`` as for ``gain``).
    declared_in : str
        Where the map comes from (recorded with it: ``"problem file"``, ``"command line"``, ...).

    Notes
    -----
    ``stretch = gain * (raw - offset)``. Mappings are stored as tuples of pairs (the map is frozen).
    """

    time: str = "t"
    time_unit: str = "s"
    columns: tuple = field(default=())
    gain: tuple = field(default=())
    offset: tuple = field(default=())
    declared_in: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.time, str) or not self.time.strip():
            raise InputError(f"time = {self.time!r}: expected the name of the time column, e.g. 't' or 'time_s'")
        if self.time_unit not in TIME_UNITS:
            raise InputError(f"time_unit = {self.time_unit!r}: expected one of {', '.join(TIME_UNITS)}")
        cols = _pairs(self.columns, "columns")
        for s, c in cols:
            if not isinstance(c, str) or not c.strip():
                raise InputError(f"columns: {s} = {c!r}: expected the name of a CSV column")
        object.__setattr__(self, "columns", tuple((s, c.strip()) for s, c in cols))
        for what in ("gain", "offset"):
            pairs = _pairs(getattr(self, what), what)
            out = []
            for s, v in pairs:
                if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
                    raise InputError(f"{what}: {s} = {v!r}: expected a number")
                v = float(v)
                if not math.isfinite(v):
                    raise InputError(f"{what}: {s} = {v!r}: expected a finite number")
                if what == "gain" and v == 0:
                    raise InputError(f"gain: {s} = 0: expected a non-zero stretch per raw unit (e.g. 1e-5 per mV)")
                out.append((s, v))
            object.__setattr__(self, what, tuple(out))
        object.__setattr__(self, "time", self.time.strip())

    @property
    def is_identity(self) -> bool:
        """The documented format as it is: ``t`` in s, sensor-named columns, gain 1, offset 0."""
        return (
            self.time == "t"
            and self.time_unit == "s"
            and all(s == c for s, c in self.columns)
            and all(v == 1.0 for _, v in self.gain)
            and all(v == 0.0 for _, v in self.offset)
        )

    def updated(self, *, time=None, time_unit=None, columns=None, gain=None, offset=None, declared_in=None):
        """This map with the given entries replaced key by key (the command line over the problem file)."""
        merged = {}
        for what, new in (("columns", columns), ("gain", gain), ("offset", offset)):
            d = dict(getattr(self, what))
            d.update(dict(_pairs(new, what)))
            merged[what] = tuple(d.items())
        return ChannelMap(
            time=self.time if time is None else time,
            time_unit=self.time_unit if time_unit is None else time_unit,
            declared_in=self.declared_in if declared_in is None else declared_in,
            **merged,
        )

    def check(self, sensor_names) -> ChannelMap:
        """Refuse names that are not sensors of the problem and a column used twice; returns ``self``."""
        names = tuple(sensor_names)
        for what in ("columns", "gain", "offset"):
            for s, _ in getattr(self, what):
                if s not in names and not (what != "columns" and s == ALL):
                    raise InputError(
                        f"{what}: {s!r}: not a sensor of the problem (expected one of {', '.join(names)}"
                        + (", or '*' for all)" if what != "columns" else ")")
                    )
        used = [self.column(s) for s in names]
        dup = next((c for c in used if used.count(c) > 1), None)
        if dup is not None:
            who = [s for s in names if self.column(s) == dup]
            raise InputError(f"columns: {' and '.join(who)} = {dup!r}: expected one column per sensor")
        if self.time in used:
            who = next(s for s in names if self.column(s) == self.time)
            raise InputError(f"columns: {who} = {self.time!r}: the time column, expected a sensor's column")
        return self

    def column(self, sensor: str) -> str:
        """The CSV column of ``sensor``."""
        return dict(self.columns).get(sensor, sensor)

    def _value(self, what: str, sensor: str, default: float) -> float:
        d = dict(getattr(self, what))
        return d.get(sensor, d.get(ALL, default))

    def calibration(self, sensor_names) -> tuple[np.ndarray, np.ndarray]:
        """``(gain, offset)`` arrays in the order of ``sensor_names``."""
        gain = np.array([self._value("gain", s, 1.0) for s in sensor_names])
        offset = np.array([self._value("offset", s, 0.0) for s in sensor_names])
        return gain, offset

    def convert(self, t, raw, sensor_names) -> tuple[np.ndarray, np.ndarray]:
        """Times in s and stretches from a file's times and raw readings (``(N,)`` and ``(N, p)``, or
        one row ``()`` and ``(p,)``): ``stretch = gain * (raw - offset)``; NaN stays NaN."""
        t = np.asarray(t, dtype=float)
        raw = np.asarray(raw, dtype=float)
        if self.is_identity:
            return t, raw
        gain, offset = self.calibration(sensor_names)
        return t * TIME_UNITS[self.time_unit], gain * (raw - offset)

    def table(self, sensor_names) -> dict:
        """The ``[measurements]`` keys of a problem file that declare this map (every sensor's entry
        written out, so that the file reads as the map does whatever it was merged from)."""
        gain, offset = self.calibration(sensor_names)
        return {
            "time": self.time,
            "time_unit": self.time_unit,
            "columns": {s: self.column(s) for s in sensor_names},
            "gain": {s: float(g) for s, g in zip(sensor_names, gain)},
            "offset": {s: float(o) for s, o in zip(sensor_names, offset)},
        }

    def as_dict(self, sensor_names) -> dict:
        """What a run records: time column and unit, each sensor's column, gain and offset, the convention."""
        gain, offset = self.calibration(sensor_names)
        out = {
            "time_column": self.time,
            "time_unit": self.time_unit,
            "columns": {s: self.column(s) for s in sensor_names},
            "gain": {s: float(g) for s, g in zip(sensor_names, gain)},
            "offset": {s: float(o) for s, o in zip(sensor_names, offset)},
            "convention": CONVENTION,
        }
        if self.declared_in:
            out["declared_in"] = self.declared_in
        return out
