"""Fast CSV path and Figure-based plots (issue 12).

* a clean numeric record is parsed by ``np.loadtxt``; a file with a problem is re-read line by line
  so the error still names its line; both paths give identical measurements;
* 1 hour of 1 kHz, 4 sensors (3.6 M rows) is read and validated by the fast path alone (slow test;
  about 5 s of CPU here, printed, never asserted: CI runs on a loaded host);
* the plotting functions build :class:`matplotlib.figure.Figure` (no backend switch), return it and
  draw into a caller's ``ax``.
"""

import time
from pathlib import Path

import numpy as np
import pytest

from wingopt.errors import DataFileError
from wingopt.measurements import csv_file as csv_data
from wingopt.measurements.csv_file import read_measurements

NAMES = ("S1", "S2", "S3", "S4")
# the tunnel stand-in: 1381 rows, 13 of them dropped frames (empty cells)
RECORD = Path(__file__).resolve().parents[1] / "examples" / "data" / "tunnel_300Hz.csv"


def write_record(path: Path, seconds: int, rate: int = 1000, gaps: bool = False) -> Path:
    rng = np.random.default_rng(0)
    pool = [",".join(f"{v:.6e}" for v in 2e-3 + 1e-5 * rng.standard_normal(4)) for _ in range(997)]
    if gaps:
        pool[5] = ",".join(["", *pool[5].split(",")[1:]])
    frac = [f"{k / rate:.3f}"[1:] for k in range(rate)]
    with open(path, "w") as fh:
        fh.write("# generated\nt,S1,S2,S3,S4\n")
        for s in range(seconds):
            fh.write("".join(f"{s}{frac[k]},{pool[(s * rate + k) % 997]}\n" for k in range(rate)))
    return path


@pytest.mark.parametrize("gaps", [False, True])
def test_fast_and_line_by_line_paths_agree(tmp_path, gaps):
    path = write_record(tmp_path / "r.csv", 3, gaps=gaps)
    text = path.read_text()
    assert csv_data._fast_table(path, text, NAMES) is not None
    fast, rep_fast = read_measurements(path, NAMES)
    slow, rep_slow = csv_data._read_slow(str(path), text, NAMES)
    np.testing.assert_array_equal(fast.t, slow.t)
    np.testing.assert_array_equal(fast.values, slow.values)
    assert rep_fast.as_dict() == rep_slow.as_dict()
    assert rep_fast.missing_rows == (len(range(5, 3000, 997)) if gaps else 0)  # an empty cell every 997 rows


def test_shipped_record_takes_the_fast_path_with_its_gaps():
    text = RECORD.read_text()
    assert csv_data._fast_table(RECORD, text, NAMES) is not None
    meas, rep = read_measurements(RECORD, NAMES)
    assert rep.rows == 1381 and rep.missing_rows == 13
    assert rep.missing_rows == sum(1 for ln in text.splitlines() if ",," in ln or ln.endswith(","))


def test_an_error_found_by_the_fast_path_names_its_line(tmp_path):
    path = write_record(tmp_path / "r.csv", 2)
    lines = path.read_text().splitlines()
    lines[1500] = lines[1400]  # time goes back at file line 1501
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataFileError, match=r"r\.csv:1501: t = 1\.398 after 1\.497"):
        read_measurements(path, NAMES)


def _fast_only(monkeypatch) -> None:
    """The line-by-line reader fails the test if it is reached: the record took the fast path."""

    def refuse(*args, **kwargs):
        raise AssertionError("the line-by-line reader was used")

    monkeypatch.setattr(csv_data, "_read_slow", refuse)


@pytest.mark.slow
def test_one_hour_at_1khz_takes_the_fast_path(tmp_path, monkeypatch):
    path = write_record(tmp_path / "hour.csv", 3600)
    _fast_only(monkeypatch)
    c0, w0 = time.process_time(), time.perf_counter()
    meas, rep = read_measurements(path, NAMES)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    assert meas.values.shape == (3_600_000, 4) and rep.missing_rows == 0
    assert meas.t[-1] == pytest.approx(3599.999) and np.all(np.isfinite(meas.values))
    print(f"1 h at 1 kHz: {cpu:.2f} s CPU, {wall:.2f} s wall")


def test_ten_minutes_at_1khz_takes_the_fast_path(tmp_path, monkeypatch):
    path = write_record(tmp_path / "ten.csv", 600)
    _fast_only(monkeypatch)
    meas, rep = read_measurements(path, NAMES)
    assert meas.values.shape == (600_000, 4) and rep.missing_rows == 0


def test_plots_are_figures_without_a_backend_switch(tmp_path):
    import matplotlib
    from matplotlib.figure import Figure

    from wingopt.plots.identify import plot_lift, plot_load_field

    backend = matplotlib.get_backend()
    t = np.linspace(0, 1, 50)
    fig = plot_lift(tmp_path / "lift.png", t, 0.4 + 0 * t, 0.01 + 0 * t, 0.41, "x")
    assert isinstance(fig, Figure) and (tmp_path / "lift.png").stat().st_size > 1000
    X, Y = np.meshgrid(np.linspace(0, 1, 5), np.linspace(0, 1, 4))
    assert isinstance(plot_load_field(None, X, Y, X * Y), Figure)
    mine = Figure()
    ax = mine.subplots()
    assert plot_lift(None, t, t, ax=ax) is mine and len(ax.lines) == 1
    assert matplotlib.get_backend() == backend
