"""Streams keep what they computed (issue 25): every estimate written so far survives a signal
(TERM, INT, HUP), a closed stdout and any error (a bad row, a numerical failure, out of memory),
with the error in one line; ``--follow`` reads a truncated or rotated file again like ``tail -F``;
memory and line length are bounded on every input; a record in the wrong scale is warned about.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from wingopt.errors import DataFileError, SolverError
from wingopt.estimation.registry import resolve
from wingopt.measurements.csv_stream import MAX_GAP_SAMPLES, CsvRowParser
from wingopt.measurements.lines import MAX_LINE_BYTES, LineSource
from wingopt.problem import load_problem
from wingopt.workflows.stream import follow

ROOT = Path(__file__).resolve().parents[1]
# The short calibration record (151 rows, a transient) feeds the streams; the scale test needs a record
# whose readings are in the plausible band (the release peaks at 0.061, above the pre-strain 0.05, and
# x1e-3 is still inside the band): the tunnel record (peak 0.0197).
RECORD = ROOT / "examples" / "data" / "tunnel_calibration_300Hz.csv"
STEADY = ROOT / "examples" / "data" / "tunnel_300Hz.csv"
LINEAR = resolve("mhe", "linear", stream=True)
CLI = [sys.executable, "-m", "wingopt", "identify", "membrane", "--mesh", "13x7", "--model", "linear"]


def _rows(path: Path) -> list[dict]:
    with open(path) as fh:
        return list(csv.DictReader(fh))


def _problem():
    return load_problem("membrane").with_mesh((13, 7))


def _env():
    return {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


# -- the line source ---------------------------------------------------------------------------------


def _read(source: LineSource, until: int, action=None) -> list[str]:
    out = []
    for line in source:
        out.append(line)
        if len(out) == until and action is not None:
            action()
    return out


@pytest.mark.parametrize("how", ["truncated", "rotated", "deleted and recreated"])
def test_a_followed_file_that_is_replaced_is_read_again_from_its_start(tmp_path, how, caplog):
    path = tmp_path / "daq.csv"
    path.write_text("a\nb\nc\n")

    def replace():
        if how == "truncated":
            path.write_text("")
            time.sleep(0.1)  # the follower sees the shorter file first
            path.write_text("d\ne\n")
        elif how == "rotated":
            path.rename(tmp_path / "daq.csv.1")
            path.write_text("d\ne\n")
        else:
            path.unlink()
            path.write_text("d\ne\n")

    src = LineSource(str(path), 0.02, 1.0, {})
    assert _read(src, 3, replace) == ["a", "b", "c", "d", "e"]
    assert len(src.restarts) == 1 and src.reason.startswith("idle")
    assert any(("truncated" if how == "truncated" else "rotated") in r.getMessage() for r in caplog.records)


def test_a_line_without_newline_is_refused_in_bounded_memory(tmp_path):
    path = tmp_path / "big.csv"
    path.write_bytes(b"t,S1\n" + b"0.001," * (MAX_LINE_BYTES // 3))
    with pytest.raises(DataFileError, match="line longer than"):
        _read(LineSource(str(path), 0.02, 1.0, {}), 0)


def test_a_stream_gap_of_too_many_samples_is_refused():
    p = CsvRowParser(("S1",), "<stdin>")
    p.feed("t,S1")
    p.feed("0,1e-3")
    p.feed("0.001,1e-3")
    with pytest.raises(DataFileError, match="gap of .* samples"):
        p.feed(f"{0.001 * (MAX_GAP_SAMPLES + 10)},1e-3")
    p = CsvRowParser(("S1", "S2"), "daq.csv")
    p.feed("t,S1,S2")
    assert len(p.feed("0,1e-3,2e-3")) == 1
    p.new_file()  # rotated: the new file's header (columns in another order), times go on
    assert p.feed("S2,t,S1") == []
    ((t, y),) = p.feed("2e-3,0.001,1e-3")  # S2, t, S1
    assert t == pytest.approx(0.001) and y.tolist() == [1e-3, 2e-3]


# -- the workflow: the record is kept whatever stops the stream -----------------------------------


class _Failing:
    """A streaming estimator whose ``push`` raises ``exc`` at sample ``at``."""

    def __init__(self, est, at, exc):
        self._est, self._at, self._exc, self._n = est, at, exc, 0

    def push(self, t, y):
        self._n += 1
        if self._n == self._at:
            raise self._exc
        return self._est.push(t, y)

    def __getattr__(self, name):
        return getattr(self._est, name)


@pytest.mark.parametrize(
    "exc, raised",
    [
        (np.linalg.LinAlgError("innovation covariance not positive definite"), SolverError),
        (OverflowError("math range error"), SolverError),
        (MemoryError(), SolverError),
        (KeyboardInterrupt(), KeyboardInterrupt),
    ],
    ids=["LinAlgError", "OverflowError", "MemoryError", "KeyboardInterrupt"],
)
def test_every_estimate_survives_an_error(tmp_path, monkeypatch, exc, raised):
    import wingopt.estimation.runners as runners

    real = runners.build
    monkeypatch.setattr(runners, "build", lambda *a, **k: _Failing(real(*a, **k), 31, exc))
    out = tmp_path / "res"
    seen = []
    with pytest.raises(raised) as info:
        follow(
            _problem(), out, source=str(RECORD), spec=LINEAR, idle_timeout=0.5, on_estimate=lambda k, r: seen.append(k)
        )
    assert len(seen) == 30 == len(_rows(out / "lift.csv"))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["rows_written"] == 30
    if raised is SolverError:
        msg = str(info.value)
        assert "\n" not in msg and "30 estimates so far" in msg and str(out) in msg
        assert summary["stopped"].startswith("error: ")
    else:
        assert summary["stopped"] == "SIGINT"


@pytest.mark.parametrize("scale", [1e-3, 1e-6])
def test_a_record_in_the_wrong_scale_is_warned_about_in_the_stream(tmp_path, scale):
    text = STEADY.read_text().splitlines()
    head = [ln for ln in text if ln.startswith(("#", "t,"))]
    body = [ln.split(",") for ln in text if ln and not ln.startswith(("#", "t,"))]
    scaled = [",".join([r[0]] + [f"{float(v) * scale:.9g}" if v else "" for v in r[1:]]) for r in body]
    src = tmp_path / "x.csv"
    src.write_text("\n".join(head + scaled) + "\n")
    summary = follow(_problem(), tmp_path / "res", source=str(src), spec=LINEAR, idle_timeout=0.3)
    hint = [w for w in summary["warnings"] if "implausibly small" in w]
    assert len(hint) == 1 and hint[0].startswith("[data check] "), summary["warnings"]  # once, naming its source
    assert all(w.startswith("[") for w in summary["warnings"]), summary["warnings"]
    plain = follow(_problem(), tmp_path / "res2", source=str(STEADY), spec=LINEAR, idle_timeout=0.3)
    assert not any("implausib" in w or "pre-strain" in w for w in plain["warnings"])


# -- the command line: signals, a closed stdout ---------------------------------------------------


def _feed(lines: list[str], hold: float):
    script = (
        "import sys, time\n"
        f"lines = {lines!r}\n"
        "for i in range(0, len(lines), 3):\n"
        "    sys.stdout.write(''.join(l + '\\n' for l in lines[i:i + 3])); sys.stdout.flush(); time.sleep(0.01)\n"
        f"time.sleep({hold})\n"
    )
    return subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE)


def _record_lines() -> list[str]:
    return [ln for ln in RECORD.read_text().splitlines() if ln and not ln.startswith("#")]


@pytest.mark.parametrize("sig", ["SIGHUP", "SIGTERM", "SIGINT"])
def test_a_signal_ends_a_stdin_stream_with_every_estimate_written(tmp_path, sig):
    writer = _feed(_record_lines(), 60)
    out = tmp_path / "res"
    proc = subprocess.Popen(
        [*CLI, "--data", "-", "--out", str(out)], stdin=writer.stdout, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, env=_env(), cwd=tmp_path, text=True,
    )  # fmt: skip
    writer.stdout.close()
    printed = []
    while len(printed) < 60:
        line = proc.stdout.readline()
        assert line, proc.stderr.read()
        if line[0].isdigit():
            printed.append(line)
    proc.send_signal(getattr(signal, sig))
    rest = proc.stdout.read()  # not communicate(): it would skip what readline() buffered
    err = proc.stderr.read()
    proc.wait(timeout=60)
    writer.kill()
    writer.wait()
    printed += [ln for ln in rest.splitlines() if ln and ln[0].isdigit()]
    assert proc.returncode == 0 and "Traceback" not in err, err
    assert len(_rows(out / "lift.csv")) == len(printed) >= 60
    assert json.loads((out / "summary.json").read_text())["stopped"] == sig


def test_a_closed_stdout_ends_the_stream_with_every_estimate_written(tmp_path):
    writer = _feed(_record_lines(), 60)
    out = tmp_path / "res"
    proc = subprocess.Popen(
        [*CLI, "--data", "-", "--out", str(out)], stdin=writer.stdout, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, env=_env(), cwd=tmp_path,
    )  # fmt: skip
    writer.stdout.close()
    got = [proc.stdout.readline() for _ in range(11)]  # the header and 10 estimates
    proc.stdout.close()
    err = proc.stderr.read().decode()
    proc.wait(timeout=60)
    writer.kill()
    writer.wait()
    assert proc.returncode == 0 and "Traceback" not in err and "Exception ignored" not in err, err
    assert len(_rows(out / "lift.csv")) >= len(got) - 1
    assert json.loads((out / "summary.json").read_text())["stopped"] == "stdout closed"


def test_a_time_jump_and_a_huge_line_end_the_stream_in_one_line_keeping_the_record(tmp_path):
    lines = _record_lines()[:151]
    for extra in ["1000000.0,1e-4,1e-4,1e-4,1e-4", "0.001," * (MAX_LINE_BYTES // 5)]:
        out = tmp_path / f"res{len(extra)}"
        run = subprocess.run(
            [*CLI, "--data", "-", "--out", str(out)], input="\n".join([*lines, extra]) + "\n", capture_output=True,
            text=True, env=_env(), cwd=tmp_path, timeout=120,
        )  # fmt: skip
        assert run.returncode == 2, run.stderr
        assert run.stderr.strip().splitlines()[-1].startswith("wingopt identify: error: <stdin>:")
        assert len(_rows(out / "lift.csv")) == 150
