"""A record's sample clock: time stamps as loggers write them, read as a uniform clock.

A logger's stamps are rounded (to 0.1 ms, say) and jitter (a few tens of µs): at 300 Hz a step of
3.3 ms is written 3.2, 3.3 or 3.4 ms. The samples themselves were taken on the DAQ's clock, so the
record is uniform: :func:`uniform_clock` fits ``t_k = t0 + n_k dt`` by least squares (``n_k`` the
sample's place on the grid; a step that is a whole multiple of the typical one is a gap, its
samples missing) and accepts stamps within :data:`MAX_JITTER` of a step of that clock; the fitted
step and the largest deviation are reported. Larger irregularity is refused: such a record was not
sampled on one clock. The CSV reader, the arrays handed to the API and a ``Measurements`` built
by hand pass the same check.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Clock", "uniform_clock", "on_clock", "jitter_note", "MAX_JITTER", "QUIET_JITTER", "IrregularSampling"]

MAX_JITTER = 0.10
"""Largest deviation of a stamp from the fitted uniform clock, in steps, read as jitter."""

QUIET_JITTER = 0.01
"""Deviation (in steps) below which the stamps are the clock itself (printed to a few digits): not
reported as jitter. The readers tolerated this much before jitter was read."""


class IrregularSampling(ValueError):
    """Stamps that no uniform clock explains; ``position``: the worst stamp's row; ``message``:
    the reason without the source's name (each reader names its source and raises its own error)."""

    def __init__(self, message: str, position: int) -> None:
        super().__init__(message)
        self.message, self.position = message, position


@dataclass(frozen=True)
class Clock:
    """A fitted uniform clock: ``t0 + index * dt``; ``max_deviation``: the largest stamp's distance to
    it (s); ``index``: each stamp's place on the grid (gaps skip places)."""

    t0: float
    dt: float
    index: np.ndarray
    max_deviation: float

    @property
    def count(self) -> int:
        """Samples on the grid, the gaps' included."""
        return int(self.index[-1]) + 1

    @property
    def grid(self) -> np.ndarray:
        return self.t0 + self.dt * np.arange(self.count)

    @property
    def jitter(self) -> float:
        """The largest deviation in steps."""
        return self.max_deviation / self.dt

    @property
    def jittered(self) -> bool:
        """Whether the stamps deviate from the clock more than their printing would (:data:`QUIET_JITTER`)."""
        return self.jitter > QUIET_JITTER

    def as_dict(self) -> dict:
        return {
            "dt_s": self.dt,
            "t0_s": self.t0,
            "max_deviation_s": self.max_deviation,
            "max_deviation_steps": self.jitter,
        }

    def note(self, source: str) -> str:
        """The warning that reports a jittered clock."""
        return jitter_note(source, self.as_dict())


def jitter_note(source: str, clock: dict) -> str:
    """The warning that reports stamps read as a uniform clock (``clock``: :meth:`Clock.as_dict`)."""
    return (
        f"{source}: time stamps jitter up to {clock['max_deviation_s']:.3g} s ({clock['max_deviation_steps']:.1%} of "
        f"a step) about a uniform clock: read as uniform samples, step {clock['dt_s']:.9g} s (least-squares fit)"
    )


def uniform_clock(t: np.ndarray, max_jitter: float = MAX_JITTER) -> Clock:
    """The uniform clock of strictly increasing stamps ``t`` (see the module docstring).

    Raises
    ------
    IrregularSampling
        A stamp more than ``max_jitter`` of a step off the fitted clock.
    """
    t = np.asarray(t, dtype=float)
    steps = np.diff(t)
    typical = float(np.median(steps))
    index = np.concatenate([[0], np.cumsum(np.maximum(np.rint(steps / typical), 1.0))]).astype(np.int64)
    # Least squares t = t0 + index dt, centred so that long records keep their digits.
    k = index - index.mean()
    dt = float(k @ (t - t.mean()) / (k @ k))
    t0 = float(t.mean() - dt * index.mean())
    dev = t - (t0 + dt * index)
    worst = int(np.argmax(np.abs(dev)))
    clock = Clock(t0, dt, index, float(np.abs(dev[worst])))
    if not clock.jittered:
        # Stamps that are the clock (printed to their digits): the grid from the first stamp and the
        # typical step, as the readers always made it (a record read before reads the same).
        clock = Clock(float(t[0]), typical, index, clock.max_deviation)
    if clock.jitter > max_jitter:
        j = max(worst, 1)
        raise IrregularSampling(
            f"irregular sampling (step {steps[j - 1]:.6g} s, typical {typical:.6g} s; a stamp {clock.jitter:.0%} of a "
            f"step off the best uniform clock, at most {max_jitter:.0%} is read as jitter): resample the data to a "
            "uniform time step",
            worst,
        )
    return clock


def on_clock(t: np.ndarray, values: np.ndarray, max_jitter: float = MAX_JITTER) -> tuple[Clock, np.ndarray, np.ndarray]:
    """The clock of ``t`` and the samples on its uniform grid: ``(clock, grid times, values)``, the
    gaps' rows missing (NaN). Raises :class:`IrregularSampling` as :func:`uniform_clock`."""
    clock = uniform_clock(t, max_jitter)
    values = np.asarray(values, dtype=float)
    if clock.count == values.shape[0]:
        return clock, clock.grid, values
    grid = np.full((clock.count,) + values.shape[1:], np.nan)
    grid[clock.index] = values
    return clock, clock.grid, grid


class RunningClock:
    """The uniform clock of a stream's stamps, fitted as they arrive.

    :meth:`place` gives each stamp its place on the grid: the nearest whole step of the clock
    fitted by least squares to the stamps so far (a place further on than the next one is a gap).
    The first ``warm_up`` stamps (default :data:`WARM_UP`) only find their places (a first step of 3.2 ms rounded from
    3.33 ms is 4 % off); later ones must be within ``max_jitter`` of a step, as
    :func:`uniform_clock` asks of a file. The grid the samples are handed on with is the clock
    fitted to the warm-up's stamps (its step to about 0.03 % with 1.5 % jitter), fixed from then on.
    While the stamps are the clock itself (within :data:`QUIET_JITTER`), the grid is the first stamp
    and the first step, as the stream reader always made it.
    """

    WARM_UP = 32

    def __init__(self, max_jitter: float = MAX_JITTER, warm_up: int = WARM_UP) -> None:
        # without a warm-up the stamps must be the clock itself (a parser that hands each row on at once)
        self.max_jitter = float(max_jitter) if warm_up else QUIET_JITTER
        self.warm_up = int(warm_up)
        self.first_t = self.first_step = None
        self.last = -1
        self.count = 0
        self.max_deviation = 0.0  # in steps, each stamp against the clock fitted before it
        self._jitter_seen = False
        self._grid: tuple[float, float] | None = None  # (t0, dt) of the samples handed on
        self._sums = np.zeros(5)  # n, n^2, t - t_first, n (t - t_first), count

    @property
    def jittered(self) -> bool:
        return self._jitter_seen

    @property
    def dt(self) -> float | None:
        """The step of the grid the samples are handed on with."""
        if self.first_step is None:
            return None
        if not self.jittered or self._sums[4] < 2:
            return self.first_step
        return (self._grid or self._fit())[1]

    def _fit(self) -> tuple[float, float]:
        sn, snn, st, snt, c = self._sums
        dt = (c * snt - sn * st) / (c * snn - sn * sn)
        return self.first_t + (st - dt * sn) / c, dt

    def time(self, index: int) -> float:
        """The grid time of place ``index``: one uniform grid, fixed when first asked for (after the
        warm-up), so that the samples handed on are evenly spaced (a spectrum needs them so)."""
        if self.first_step is None:
            return self.first_t
        if not self.jittered:
            return self.first_t + index * self.first_step
        if self._grid is None:
            self._grid = self._fit()
        t0, dt = self._grid
        return t0 + index * dt

    def place(self, t: float) -> int:
        """The grid place of stamp ``t`` (raises :class:`IrregularSampling` off the clock)."""
        if self.first_t is None:
            self.first_t, n = t, 0
        elif self.first_step is None:
            self.first_step, n = t - self.first_t, 1
        else:
            t0, dt = self._fit() if self._sums[4] >= 2 else (self.first_t, self.first_step)
            n = int(round((t - t0) / dt))
            deviation = abs(t - t0 - n * dt) / dt
            tolerance = 0.5 if self.count < self.warm_up else self.max_jitter
            if n <= self.last or deviation > tolerance:
                raise IrregularSampling(
                    f"irregular sampling (step {t - self.time(self.last):.6g} s, sample period {dt:.6g} s; a stamp "
                    f"{deviation:.0%} of a step off the uniform clock, at most {self.max_jitter:.0%} is read as "
                    "jitter): resample the data to a uniform time step",
                    self.count,
                )
            # during the warm-up the deviation holds the provisional clock's error too: it decides
            # whether the stamps jitter, the reported figure comes from the stamps after it
            self._jitter_seen = self._jitter_seen or deviation > QUIET_JITTER
            if self.count >= self.warm_up:
                self.max_deviation = max(self.max_deviation, deviation)
        self._sums += (n, n * n, t - self.first_t, n * (t - self.first_t), 1.0)
        self.last, self.count = n, self.count + 1
        return n

    def as_dict(self) -> dict:
        t0, dt = (self.time(0), self.dt) if self._sums[4] >= 2 else (0.0, 0.0)
        return {
            "dt_s": dt,
            "t0_s": t0,
            "max_deviation_s": self.max_deviation * dt,
            "max_deviation_steps": self.max_deviation,
        }
