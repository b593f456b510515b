"""A membrane problem's ``[measurements]`` table: how a DAQ file's columns become stretch series.

::

    [measurements]
    time = "time_s"                    # the time column (default "t")
    time_unit = "s"                    # "s", "ms" or "us"
    columns = { S1 = "ch1", S2 = "ch2", S3 = "ch3", S4 = "ch4" }   # sensor = CSV column
    gain = { S1 = 1.0e-5, S2 = 1.0e-5, S3 = 1.1e-5, S4 = 0.9e-5 }  # stretch per raw unit (or one number for all)
    offset = { S1 = 250.0, S2 = 248.5, S3 = 251.0, S4 = 250.2 }    # raw reading at zero stretch (or one number)

    acquisition = "delta-sigma"        # how the DAQ sampled: "point" (default), "delta-sigma", or a table:
    # acquisition = { kind = "butterworth", order = 4, cutoff_hz = 100.0 }
    # acquisition = { kind = "fir", passband = 0.4, stopband = 0.6, taps = 255 }
    # acquisition = { kind = "delta-sigma", delay_s = 0.0267 }   # a group delay the stamps keep

``stretch = gain * (raw - offset)`` (:mod:`wingopt.measurements.channels`). ``acquisition`` is the
DAQ's anti-aliasing filter (:class:`~wingopt.measurements.acquisition.Acquisition`): the spectral
fits use its transfer function. Every key is optional;
sensors not named keep their own column name, gain 1 and offset 0. ``wingopt identify --columns
--gain --offset --time-column --time-unit`` override the table key by key. A bad value (a name that
is not a sensor, a zero or non-finite gain, a column used twice) is one line naming it.
"""

from __future__ import annotations

from wingopt.errors import InputError, ProblemFileError
from wingopt.measurements.acquisition import Acquisition
from wingopt.measurements.channels import ALL, TIME_UNITS, ChannelMap
from wingopt.problem.fields import Table

__all__ = ["measurements_from_table", "measurements_and_acquisition"]


def _mapping(t: Table, key: str, names: tuple[str, ...], number: bool):
    value = t.peek(key)
    if value is None:
        return None
    if number and isinstance(value, (int, float)) and not isinstance(value, bool):
        t._take(key, None, "")
        return {ALL: value}
    what = (
        "a table of sensor = " + ("number" if number else '"column"') + (" (or one number for all)" if number else "")
    )
    if not isinstance(value, dict):
        raise t.error(key, value, what)
    for s, v in value.items():
        if s not in names:
            raise t.error(f"{key}.{s}", v, f"a sensor of the problem ({', '.join(names)})")
        ok = (isinstance(v, (int, float)) and not isinstance(v, bool)) if number else isinstance(v, str)
        if not ok:
            raise t.error(f"{key}.{s}", v, "a number" if number else "a column name (a string)")
    t._take(key, None, "")
    return value


def measurements_from_table(t: Table, sensor_names) -> ChannelMap:
    """Validate a ``[measurements]`` table against the problem's sensors (unknown keys refused)."""
    return measurements_and_acquisition(t, sensor_names)[0]


def _acquisition(t: Table) -> Acquisition | None:
    if not t.has("acquisition"):
        return None
    value = t.peek("acquisition")
    try:
        acq = Acquisition.from_value(value)
    except InputError as exc:
        raise ProblemFileError(f"{t.source}: [measurements] {exc}") from None
    t._take("acquisition", None, "")
    return acq


def measurements_and_acquisition(t: Table, sensor_names) -> tuple[ChannelMap, Acquisition | None]:
    """The ``[measurements]`` table's channel map and its declared acquisition (``None``: undeclared)."""
    names = tuple(sensor_names)
    acquisition = _acquisition(t)
    time = t.string("time", "t")
    unit = t.string("time_unit", "s", choices=tuple(TIME_UNITS))
    columns = _mapping(t, "columns", names, number=False)
    gain = _mapping(t, "gain", names, number=True)
    offset = _mapping(t, "offset", names, number=True)
    t.finish()
    try:
        cmap = ChannelMap(time, unit, columns, gain, offset, declared_in=f"{t.source} [measurements]").check(names)
        return cmap, acquisition
    except InputError as exc:
        raise ProblemFileError(f"{t.source}: [measurements] {exc}") from None
