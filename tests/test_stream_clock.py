"""A stream's time stamps as loggers write them: rounded and jittered, read on one uniform clock (issue 32)."""

import numpy as np
import pytest

from wingopt.errors import DataFileError
from wingopt.measurements.clock import IrregularSampling, RunningClock
from wingopt.measurements.csv_stream import CsvRowParser

DT = 1 / 300


def _stamps(n: int, jitter: float, seed: int = 0) -> np.ndarray:
    """300 Hz stamps with uniform jitter (a fraction of a step), rounded to 0.1 ms as a logger writes them."""
    t = DT * np.arange(n) + jitter * DT * np.random.default_rng(seed).uniform(-1, 1, n)
    return np.round(t, 4)


def test_rounded_jittered_stamps_find_their_places_and_one_uniform_grid():
    clock = RunningClock()
    places = [clock.place(t) for t in _stamps(600, 0.015)]
    assert places == list(range(600))
    assert clock.jittered and 0.015 < clock.max_deviation < 0.1
    grid = np.array([clock.time(k) for k in range(600)])
    assert np.ptp(np.diff(grid)) < 1e-15  # evenly spaced: a spectrum takes it
    assert clock.dt == pytest.approx(DT, rel=3e-4)  # the warm-up's 32 stamps fix the step to 0.03 %
    assert abs(grid[-1] - (599 * DT)) < 0.1 * DT


def test_a_gap_skips_places_and_the_stamps_of_one_clock_are_the_clock():
    clock = RunningClock()
    t = DT * np.arange(100)
    places = [clock.place(x) for x in np.delete(t, [50, 51])]
    assert places == [k for k in range(100) if k not in (50, 51)]
    assert not clock.jittered and clock.time(7) == 7 * clock.first_step  # the grid the reader always made


def test_a_clock_that_no_uniform_clock_explains_is_refused():
    clock = RunningClock()
    t = DT * np.arange(200) + 0.2 * DT * np.random.default_rng(1).uniform(-1, 1, 200)
    with pytest.raises(IrregularSampling, match="irregular sampling"):
        for x in np.sort(t):
            clock.place(x)


def test_the_stream_parser_holds_its_warm_up_and_hands_on_a_uniform_grid():
    p = CsvRowParser(("S1",), "daq.csv", warm_up=RunningClock.WARM_UP)
    assert p.feed("t,S1") == []
    rows = []
    for k, t in enumerate(_stamps(100, 0.015, seed=2)):
        out = p.feed(f"{t:.4f},{1e-3 + 1e-6 * k}")
        assert out == [] if k < RunningClock.WARM_UP - 1 else len(out) >= 1
        rows += out
    rows += p.flush()
    times = np.array([r[0] for r in rows])
    assert len(rows) == 100 and np.ptp(np.diff(times)) < 1e-15
    assert p.clock is not None and p.clock["max_deviation_steps"] > 0.01
    short = CsvRowParser(("S1",), "daq.csv", warm_up=RunningClock.WARM_UP)
    short.feed("t,S1")
    assert all(short.feed(f"{t:.4f},1e-3") == [] for t in _stamps(5, 0.015))
    assert len(short.flush()) == 5  # a record shorter than the warm-up is handed on at its end


def test_without_a_warm_up_the_parser_keeps_its_one_percent():
    p = CsvRowParser(("S1",), "daq.csv")
    p.feed("t,S1")
    for k in range(3):
        assert len(p.feed(f"{k * DT:.7f},1e-3")) == 1
    with pytest.raises(DataFileError, match="daq.csv:5: irregular sampling"):
        p.feed("0.0105,1e-3")  # 3.15 steps
