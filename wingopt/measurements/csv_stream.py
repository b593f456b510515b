"""Parsing a sensor CSV line by line, for a stream that grows (``wingopt identify --follow``).

Same format and checks as :func:`wingopt.measurements.csv_file.read_measurements` (header with
``t`` and one column per sensor, ``#`` comments, empty cells / ``nan`` / ``NA`` missing, values
that cannot be a stretch refused), applied one row at a time: the sample period is the first time
step; a later step that is a whole multiple of it is a gap, filled with missing rows; any other
step is refused. A comment line ``# end`` (any case) marks the end of the stream. A
:class:`~wingopt.measurements.channels.ChannelMap` names a DAQ's columns and converts its raw
readings (``stretch = gain * (raw - offset)``), as for the batch reader.
"""

from __future__ import annotations

import csv
import math
import re

import numpy as np

from wingopt.errors import DataFileError
from wingopt.measurements.channels import ChannelMap
from wingopt.measurements.clock import IrregularSampling, RunningClock
from wingopt.measurements.csv_file import MAX_STRETCH, _cell, _ignored, header_columns, units_hint

__all__ = ["CsvRowParser", "END_MARKER"]

END_MARKER = "# end"
"""A line ``# end`` (case and inner spaces free) ends the stream."""

_END = re.compile(r"#\s*end\s*", re.IGNORECASE)

MAX_GAP_SAMPLES = 100_000
"""Longest gap (in samples) a stream may have: filling it costs one estimator step per sample; a
longer one (a clock reset, seconds written as milliseconds) ends the stream with an error."""


class CsvRowParser:
    """Turns CSV lines into uniformly sampled rows ``(t, values)``; one instance per stream.

    Parameters
    ----------
    sensor_names : sequence of str
        The problem's sensors, in its order.
    source : str
        Name used in error messages (file name or ``<stdin>``).
    channels : ChannelMap, optional
        The time and sensor columns and each sensor's gain and offset (default: ``t`` and the
        sensor names, stretch as it is).
    warm_up : int
        Rows held back while the sample clock is found (:class:`RunningClock`): with it, stamps
        as loggers write them (rounded, jittered up to 10 % of a step) are read; without it (0) each
        row is handed on at once and the stamps must be the clock itself (within 1 %).

    Attributes
    ----------
    ended : bool
        The end marker was read.
    rows, missing_rows, gap_rows : int
        Data rows read, rows with a missing value, rows inserted for gaps.
    ignored_columns : list of str
    """

    def __init__(
        self, sensor_names, source: str = "<stream>", channels: ChannelMap | None = None, warm_up: int = 0
    ) -> None:
        self.sensor_names = tuple(sensor_names)
        if channels is not None and not isinstance(channels, ChannelMap):
            raise DataFileError(f"channels = {channels!r}: expected a wingopt.measurements.ChannelMap or None")
        self.channels = (channels or ChannelMap()).check(self.sensor_names)
        self.source = source
        self.line = 0
        self.ended = False
        self.rows = self.missing_rows = self.gap_rows = 0
        self.ignored_columns: list[str] = []
        self._cols: list[int] | None = None
        self._header_names: list[str] = []
        self._it = 0
        self._ncol = 0
        self._clock = RunningClock(warm_up=warm_up)  # stamps as loggers write them, on one uniform clock
        self._clock_index = -1  # place of the last row handed on, on the uniform grid
        self._held: list[tuple[int, np.ndarray]] = []
        self._t_last = None
        self._new_file = False

    def new_file(self) -> None:
        """The lines now come from a new file (the followed file was truncated or rotated): its
        first line may be the header again (read anew: the columns may move); times go on."""
        self._new_file = True
        self.line = 0

    @property
    def dt(self) -> float | None:
        return self._clock.dt

    @property
    def clock(self) -> dict | None:
        """The fitted clock (:meth:`RunningClock.as_dict`) when the stamps jitter about it, else ``None``."""
        return self._clock.as_dict() if self._clock.jittered else None

    def feed(self, line: str) -> list[tuple[float, np.ndarray]]:
        """Parse one line (without its newline); returns the samples it yields (gap rows first)."""
        self.line += 1
        text = line.strip()
        if self.line == 1:
            text = text.lstrip("\ufeff")
        if not text:
            return []
        if text.startswith("#"):
            if _END.fullmatch(text):
                self.ended = True
            return []
        if self.ended:
            raise DataFileError(f"{self.source}:{self.line}: data after the end marker {END_MARKER!r}")
        try:
            row = next(csv.reader([text]))
        except csv.Error as exc:
            raise DataFileError(f"{self.source}:{self.line}: not a CSV line ({exc})") from None
        if self._new_file:
            self._new_file = False
            if self.channels.time in (h.strip() for h in row):  # the header again, at the top of the new file
                self._header(row)
                return []
        if self._cols is None:
            self._header(row)
            return []
        return self._row(row)

    def _header(self, row: list[str]) -> None:
        name, ln = self.source, self.line
        header = [h.strip() for h in row]
        self._it, self._cols = header_columns(name, ln, header, self.sensor_names, self.channels)
        self._ncol = len(header)
        self._header_names = header
        self.ignored_columns = _ignored(header, self.sensor_names, self.channels)

    def _row(self, row: list[str]) -> list[tuple[float, np.ndarray]]:
        name, ln = self.source, self.line
        if len(row) != self._ncol:
            raise DataFileError(f"{name}:{ln}: {len(row)} values for {self._ncol} columns")
        t = _cell(row[self._it], ln, self.channels.time, name)
        if math.isnan(t):
            raise DataFileError(f"{name}:{ln}: {self.channels.time} is missing: every row needs a time")
        raw = np.array([_cell(row[c], ln, self._header_names[c], name) for c in self._cols])
        t, vals = self.channels.convert(t, raw, self.sensor_names)
        t = float(t)
        finite = vals[np.isfinite(vals)]
        if finite.size and float(np.max(np.abs(finite))) > MAX_STRETCH:
            raise DataFileError(
                f"{name}:{ln}: sensor value {float(np.max(np.abs(finite))):.4g}: expected the dimensionless stretch "
                f"(typically 1e-4..1e-1); {units_hint(self.channels)}"
            )
        out: list[tuple[float, np.ndarray]] = []
        if self._t_last is not None:
            step = t - self._t_last
            if not step > 0:
                raise DataFileError(
                    f"{name}:{ln}: t = {t!r} after {self._t_last!r}: expected strictly increasing times"
                )
            if self._clock.dt is not None and not step / self._clock.dt <= MAX_GAP_SAMPLES:
                raise DataFileError(
                    f"{name}:{ln}: t = {t!r} after {self._t_last!r}: a gap of {step / self._clock.dt:.3g} samples "
                    f"(more than {MAX_GAP_SAMPLES}): expected a stream with short gaps (was the clock reset, or the "
                    "unit changed?)"
                )
        try:
            index = self._clock.place(t)
        except IrregularSampling as exc:
            raise DataFileError(f"{name}:{ln}: {exc.message}") from None
        self._t_last = t
        self.rows += 1
        self.missing_rows += int(np.isnan(vals).any())
        # The first rows wait until the clock is known (its first step may be a rounded 3.2 ms of 3.33):
        # the estimator takes its sample period from the first two times it is given.
        self._held.append((index, vals))
        if self._clock.count < self._clock.warm_up:
            return out
        return out + self.flush()

    def flush(self) -> list[tuple[float, np.ndarray]]:
        """The rows held back while the clock was being found, on its uniform grid (gap rows filled);
        call it when the input ends."""
        out: list[tuple[float, np.ndarray]] = []
        for index, vals in self._held:
            for gap in range(self._clock_index + 1, index):  # a gap: missing rows on the uniform grid
                self.gap_rows += 1
                out.append((self._clock.time(gap), np.full(len(self._cols), np.nan)))
            self._clock_index = index
            out.append((self._clock.time(index), vals))
        self._held.clear()
        return out
