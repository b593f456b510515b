"""Reading and validating measured stretch-sensor series from CSV (spec §2, §7).

Format: a header row with a ``t`` column (seconds) and one column per sensor, named as in the
problem file (any order; other columns are ignored and reported); one row per sample; comma
separated; lines starting with ``#`` are comments. Empty cells, ``nan`` or ``NA`` mark missing
values: such rows are kept as missing samples (the estimators skip them, nothing is invented)
and counted.

Checks, each a one-line :class:`~wingopt.errors.DataFileError` (exit code 2 on the command line):
empty file or no data rows, missing ``t`` or sensor columns, a non-numeric cell (with its line),
a missing time, times not strictly increasing, irregular sampling (stamps more than 10 % of a step
off the best uniform clock, :mod:`~wingopt.measurements.clock`: rounded or jittered stamps within
it are read as that clock and reported; whole multiples of the step are gaps and are filled with
missing rows), and
values that cannot be the dimensionless stretch ``s = alpha/(2A) ∫ |grad w|^2`` (a hint about
units: percent or microstrain).

A DAQ file with its own column names and units (``time_s,ch1,ch2,...`` in mV) is read through a
:class:`~wingopt.measurements.channels.ChannelMap` (``channels``): the columns it names, converted
by ``stretch = gain * (raw - offset)`` before these checks.
"""

from __future__ import annotations

import csv
import io
import logging
import math
import os
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wingopt.errors import DataFileError
from wingopt.measurements.channels import CONVENTION as CONVENTION_TEXT
from wingopt.measurements.channels import ChannelMap
from wingopt.measurements.clock import IrregularSampling, uniform_clock
from wingopt.measurements.series import Measurements

__all__ = ["CsvReport", "read_measurements", "MISSING_TOKENS", "MAX_STRETCH"]

log = logging.getLogger(__name__)

MISSING_TOKENS = frozenset({"", "nan", "na", "n/a", "null", "none", "-"})

MAX_STRETCH = 0.5
"""Largest plausible stretch output: ``s = 0.5`` means surface slopes of 45° on average over a
sensor, far beyond a pre-tensioned membrane; larger values are almost surely other units."""


@dataclass
class CsvReport:
    """What the reader found: sizes, missing rows, filled gaps, ignored columns, sample period."""

    path: str
    rows: int
    dt: float
    missing_rows: int
    gap_rows_filled: int
    ignored_columns: list[str] = field(default_factory=list)
    channels: dict | None = None
    clock: dict | None = None
    """The fitted clock of jittered stamps (:func:`~wingopt.measurements.clock.uniform_clock`)."""

    def as_dict(self) -> dict:
        extra = {} if self.channels is None else {"channels": self.channels}
        if self.clock is not None:
            extra["clock"] = self.clock
        return {
            "file": self.path,
            "rows": self.rows,
            "dt_s": self.dt,
            "missing_rows": self.missing_rows,
            "gap_rows_filled": self.gap_rows_filled,
            "ignored_columns": self.ignored_columns,
            **extra,
        }


def _cell(text: str, line: int, column: str, path: str) -> float:
    s = text.strip()
    if s.lower() in MISSING_TOKENS:
        return math.nan
    try:
        v = float(s)
    except ValueError:
        raise DataFileError(f"{path}:{line}: {column} = {text!r}: expected a number (or empty for missing)") from None
    if math.isinf(v):
        raise DataFileError(f"{path}:{line}: {column} = {text!r}: expected a finite number")
    return v


def _iter(values):
    try:
        return list(values)
    except TypeError:
        return [None]


MAX_LINE_CHARS = 1 << 20
"""Longest line of a CSV record (1 MiB: a row of a few thousand sensors); longer is refused."""


def _read_text(path: str | Path) -> str:
    p = Path(path)
    name = str(path)
    if p.is_dir():
        raise DataFileError(f"data = {name!r}: is a directory, expected a CSV file")
    if p.exists() and not p.is_file():
        raise DataFileError(f"data = {name!r}: not a regular file (a device, a pipe): expected a CSV file")
    if not p.is_file():
        raise DataFileError(f"data = {name!r}: no such file")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise DataFileError(f"{name}: not a text (UTF-8) CSV file") from None
    except OSError as exc:
        raise DataFileError(f"{name}: cannot read: {exc.strerror}") from None
    # A window of MAX_LINE_CHARS characters without a newline: a line at least that long (any line
    # twice as long is caught; L / MAX_LINE_CHARS fast searches, nothing copied).
    for start in range(0, len(text) - MAX_LINE_CHARS + 1, MAX_LINE_CHARS):
        if text.find("\n", start, start + MAX_LINE_CHARS) < 0:
            number = text.count("\n", 0, start) + 1
            raise DataFileError(
                f"{name}:{number}: a line longer than {MAX_LINE_CHARS} characters: not a CSV of sensor readings "
                "(a header or a row of a few sensors is short)"
            )
    if "\0" in text:
        line = text.count("\n", 0, text.index("\0")) + 1
        raise DataFileError(f"{name}:{line}: a NUL byte: not a text CSV file")
    return text


_EMPTY_CELL = re.compile(r"(?<=,)[ \t]*(?=,|$)|^[ \t]*(?=,)", re.MULTILINE)


def _fast_table(
    path, text: str, sensor_names, channels: ChannelMap | None = None
) -> tuple[np.ndarray, np.ndarray, list[str]] | None:
    """``np.loadtxt`` on a clean file: ``(t, values, ignored columns)``, or ``None`` to use the validator.

    Applies only to plain numeric files (empty cells and ``nan`` allowed, no quotes): anything else,
    and any file with a problem, goes through the line-by-line reader, which reports the line.
    """
    if '"' in text:
        return None
    start = 0
    while True:  # header: the first line that is neither blank nor a comment
        end = text.find("\n", start)
        line = text[start : None if end < 0 else end]
        if line.strip() and not line.lstrip().startswith("#"):
            break
        if end < 0:
            return None
        start = end + 1
    header = [h.strip() for h in line.split(",")]
    channels = channels or ChannelMap()
    tcol, cols = channels.time, [channels.column(n) for n in sensor_names]
    if tcol not in header or len(set(header)) != len(header) or any(c not in header for c in cols):
        return None
    body = text[start + len(line) :]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "empty input" is handled below
            if ",," in body or ",\n" in body or "\n," in body or body.startswith(",") or body.rstrip().endswith(","):
                # empty cells are missing samples: spelled out for loadtxt (the regex only when needed)
                src = io.StringIO(_EMPTY_CELL.sub("nan", body))
                table = np.loadtxt(src, delimiter=",", comments="#", ndmin=2, dtype=float)
            else:  # straight from the file: 3x less CPU than from a string buffer
                skip = text.count("\n", 0, start) + 1
                table = np.loadtxt(
                    path, delimiter=",", comments="#", skiprows=skip, ndmin=2, dtype=float, encoding="utf-8-sig"
                )
    except ValueError:
        return None
    if table.shape[0] < 2 or table.shape[1] != len(header) or np.isinf(table).any():
        return None
    t = table[:, header.index(tcol)]
    vals = table[:, [header.index(c) for c in cols]]
    if np.isnan(t).any():
        return None
    return t, vals, _ignored(header, sensor_names, channels)


def _ignored(header, sensor_names, channels: ChannelMap) -> list[str]:
    used = {channels.time, *(channels.column(n) for n in sensor_names)}
    return [h for h in header if h not in used]


def read_measurements(
    path: str | Path, sensor_names: tuple[str, ...] | list[str], channels: ChannelMap | None = None
) -> tuple[Measurements, CsvReport]:
    """Read a measured record (CSV) for the given sensor names (problem order).

    A clean numeric file is parsed by ``np.loadtxt`` (1 h of 1 kHz, 4 sensors in ~3 s); a file with
    any problem is re-read line by line so that the error names its line.

    Parameters
    ----------
    path : str or Path
        CSV file: a ``t`` column (s) and one column per sensor, headers = sensor names.
    sensor_names : sequence of str
        The problem's sensor names, in its order.
    channels : ChannelMap, optional
        The time and sensor columns and each sensor's ``gain`` and ``offset`` (``stretch = gain *
        (raw - offset)``) of a DAQ file; ``None``: ``t`` in s and one stretch column per sensor name.

    Returns
    -------
    Measurements
        NaN where missing, on a uniform time grid.
    CsvReport
        What was read: rows, missing rows and gaps, ignored columns, the channel map (when one is given).
    """
    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)) or not str(path).strip():
        raise DataFileError(f"path = {path!r}: expected the path of a CSV file")
    if isinstance(sensor_names, (str, bytes)) or not all(isinstance(n, str) for n in _iter(sensor_names)):
        raise DataFileError(
            f"sensor_names = {sensor_names!r}: expected a sequence of sensor names, e.g. ('S1', 'S2', 'S3', 'S4')"
        )
    sensor_names = tuple(sensor_names)
    if not sensor_names:
        raise DataFileError("sensor_names = (): expected at least one sensor name")
    if channels is not None and not isinstance(channels, ChannelMap):
        raise DataFileError(f"channels = {channels!r}: expected a wingopt.measurements.ChannelMap or None")
    given = channels is not None
    channels = (channels or ChannelMap()).check(sensor_names)
    name = str(path)
    text = _read_text(path)
    fast = _fast_table(path, text, sensor_names, channels)
    if fast is not None:
        t, vals, ignored = fast
        try:
            return _finish(name, t, vals, None, sensor_names, ignored, channels, given)
        except _NeedLines:
            pass
    return _read_slow(name, text, sensor_names, channels, given)


class _NeedLines(Exception):
    """An error was found by the fast path: re-read line by line to name the line."""


def _read_slow(
    name: str, text: str, sensor_names, channels: ChannelMap | None = None, given: bool = False
) -> tuple[Measurements, CsvReport]:
    channels = channels or ChannelMap()
    lines = [(i + 1, ln) for i, ln in enumerate(text.splitlines()) if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        want = ",".join([channels.time, *(channels.column(s) for s in sensor_names)])
        raise DataFileError(f"{name}: empty file: expected a header '{want}' and data rows")
    reader = csv.reader([ln for _, ln in lines])
    rows = list(reader)
    header = [h.strip() for h in rows[0]]
    if len(header) == 1 and (";" in header[0] or "\t" in header[0]):
        raise DataFileError(f"{name}:{lines[0][0]}: header {header[0]!r}: expected comma-separated columns")
    it, cols = header_columns(name, lines[0][0], header, sensor_names, channels)
    if len(rows) < 2:
        raise DataFileError(f"{name}: header only, no data rows")
    ignored = _ignored(header, sensor_names, channels)
    t = np.empty(len(rows) - 1)
    vals = np.empty((len(rows) - 1, len(cols)))
    for r, row in enumerate(rows[1:]):
        line = lines[r + 1][0]
        if len(row) != len(header):
            raise DataFileError(f"{name}:{line}: {len(row)} values for {len(header)} columns")
        t[r] = _cell(row[it], line, channels.time, name)
        if math.isnan(t[r]):
            raise DataFileError(f"{name}:{line}: {channels.time} is missing: every row needs a time")
        for j, c in enumerate(cols):
            vals[r, j] = _cell(row[c], line, header[c], name)
    return _finish(name, t, vals, [ln for ln, _ in lines[1:]], sensor_names, ignored, channels, given)


def _finish(name, t, vals, line_numbers, sensor_names, ignored, channels, given) -> tuple[Measurements, CsvReport]:
    """Checks on the arrays (``line_numbers[k]``: file line of data row ``k``; ``None``: fast path),
    after the channel map's conversion (the one place it is applied to a whole record)."""

    def line(k: int) -> int:
        if line_numbers is None:
            raise _NeedLines
        return line_numbers[k]

    if t.size < 2:
        raise DataFileError(f"{name}: only {t.size} data row: expected a time series")
    t, vals = channels.convert(t, vals, sensor_names)
    steps = np.diff(t)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        k = bad[0] + 1
        raise DataFileError(
            f"{name}:{line(k)}: t = {float(t[k])!r} after {float(t[k - 1])!r}: expected strictly increasing times"
        )
    try:
        clock = uniform_clock(t)
    except IrregularSampling as exc:
        raise DataFileError(f"{name}:{line(exc.position)}: {exc.message}") from None
    dt, index, n = clock.dt, clock.index, clock.count
    # Whole-multiple steps are gaps: filled with missing rows so the time grid is uniform. A step
    # that is a huge multiple would allocate the whole gap: refuse it (e.g. ms and s mixed up).
    if n > 10 * t.size + 1000:
        k = int(np.argmax(np.diff(index))) + 1
        raise DataFileError(
            f"{name}:{line(k)}: a gap of {int(index[k] - index[k - 1])} samples (step {steps[k - 1]:.6g} s, typical "
            f"{dt:.6g} s): expected a record with few missing samples"
        )
    if clock.jittered:
        log.info("%s", clock.note(name))  # the data checks report it (Measurements.clock)
    grid_vals = np.full((n, len(sensor_names)), np.nan)
    grid_vals[index] = vals
    grid_t = clock.grid
    finite = grid_vals[np.isfinite(grid_vals)]
    if finite.size == 0:
        raise DataFileError(f"{name}: every sensor value is missing")
    peak = float(np.max(np.abs(finite)))
    if peak > MAX_STRETCH:
        raise DataFileError(
            f"{name}: sensor values up to {peak:.4g}: expected the dimensionless stretch s = alpha/(2A) ∫|grad w|^2 "
            f"(typically 1e-4..1e-1); {units_hint(channels)}"
        )
    missing_rows = int(np.count_nonzero(np.isnan(vals).any(axis=1)))
    meas = Measurements(
        t=grid_t,
        values=grid_vals,
        sensor_names=tuple(sensor_names),
        source=name,
        clock=clock.as_dict() if clock.jittered else None,
    )
    report = CsvReport(
        name,
        int(t.size),
        dt,
        missing_rows,
        int(n - t.size),
        ignored,
        channels.as_dict(sensor_names) if given else None,
        clock.as_dict() if clock.jittered else None,
    )
    return meas, report


def units_hint(channels: ChannelMap) -> str:
    """The end of the message on values too large to be a stretch."""
    if channels.gain or channels.offset:
        return f"check the channel map's gain and offset ({channels.declared_in or 'given'}: {CONVENTION_TEXT})"
    return "are the values in percent or microstrain (or raw DAQ units: give each sensor's gain and offset)?"


def header_columns(
    name: str, line: int, header: list[str], sensor_names, channels: ChannelMap | None = None
) -> tuple[int, list[int]]:
    """Columns of the time and of each sensor (problem order) in a CSV header, or a one-line error.

    ``channels`` names the columns (default: ``t`` and the sensor names)."""
    channels = channels or ChannelMap()
    mapped = bool(channels.columns) or channels.time != "t"
    if channels.time not in header:
        what = (
            f"the time column {channels.time!r} (channel map)" if channels.time != "t" else "a 't' column (time in s)"
        )
        raise DataFileError(f"{name}:{line}: header {header}: expected {what}")
    missing = [s for s in sensor_names if channels.column(s) not in header]
    if missing:
        if mapped:
            cols = ", ".join(s if channels.column(s) == s else f"{channels.column(s)} ({s})" for s in missing)
            raise DataFileError(
                f"{name}:{line}: missing column(s) {cols}: expected the columns the channel map names "
                f"(header {', '.join(header)})"
            )
        raise DataFileError(
            f"{name}:{line}: missing sensor column(s) {', '.join(missing)}: expected one column per sensor "
            f"of the problem ({', '.join(sensor_names)})"
        )
    dup = next((h for h in header if header.count(h) > 1), None)
    if dup is not None:
        raise DataFileError(f"{name}:{line}: column {dup!r} appears twice")
    return header.index(channels.time), [header.index(channels.column(s)) for s in sensor_names]
