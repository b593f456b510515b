"""What the commands print says what happened: the route in words, frames x points for DIC, the
band marked 1 sd, CPU and wall time, a warning count equal to the warning lines printed; errors
that name the option; refusals before any stage line; design-sensors' stage lines."""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path

import pytest

import wingopt.cli as cli
from wingopt.cli import main
from wingopt.cli.identify import _print, route_words
from wingopt.errors import InputError
from wingopt.estimation.core.sanity import check_time_step
from wingopt.workflows.design import DesignProgress

ROOT = Path(__file__).resolve().parents[1]


def _args(**kw):
    return argparse.Namespace(json=False, out="runs/x", **kw)


def test_route_words_name_the_route_and_the_frames():
    steady = {"route": "steady", "method": "batch", "lift_N": 1.76}
    assert route_words(steady) == "steady (batch)"
    dic = {
        "route": "full field (DIC)",
        "method": "fullfield",
        "lift_N": 1.72,
        "estimator": {"frames": {"total": 3, "used": 3, "points": 800}, "steady_lift_N": 1.72},
    }
    assert route_words(dic) == "full field (DIC), 3 frames x 800 points, steady fit of their mean"
    dic["estimator"]["steady_lift_N"] = 1.5  # a time-resolved answer is not called steady
    assert route_words(dic) == "full field (DIC), 3 frames x 800 points"


def test_the_summary_line_marks_the_band_cpu_wall_and_counts_the_printed_warnings(capsys):
    handler = logging.StreamHandler()  # as the command's handler: the count is what passes it
    handler.addFilter(cli._WARNINGS)
    cli._WARNINGS.count = 0
    log = logging.getLogger("wingopt.test_console")
    log.addHandler(handler)
    log.propagate = False  # an earlier main() in this process left its own counting handler on the root
    try:
        for k in range(4):
            log.warning("warning %d", k)
    finally:
        log.removeHandler(handler)
        log.propagate = True
    summary = {"route": "transient", "method": "mhe", "lift_N": 1.2345, "lift_std_N": 0.0612, "wall_s": 1.11}
    summary["status"] = "converged"
    _print(summary, _args(), cpu_s=2.5)
    line = capsys.readouterr().out.strip()
    assert line.startswith("transient (mhe): lift 1.2345 N ± 0.061 N (1 sd) [converged]")
    assert "2.5 s CPU, 1.11 s wall -> runs/x" in line
    assert line.endswith("(4 warnings above; summary.json lists them)")
    assert cli.warnings_printed() == 4


def test_the_ms_time_error_names_the_option():
    with pytest.raises(InputError, match=r"--time-unit ms") as exc:
        check_time_step(3.3333, "daq.csv")
    assert "multiply" not in str(exc.value)
    with pytest.raises(InputError, match=r"--time-unit us"):
        check_time_step(3333.3, "daq.csv")


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--modes", "100000"], "--modes 100000: expected 1..325"),
        (["--stride", "1e9s"], "--stride 1e9s: longer than the window"),
        (["--stride", "300", "--window", "200"], "--stride 300: longer than the window"),
    ],
)
def test_sizes_are_refused_before_any_stage_line(tmp_path, capsys, extra, message):
    code = main(["identify", "membrane", "--load", "L1", "--out", str(tmp_path / "o"), *extra])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err
    assert "simulating" not in err and "estimator" not in err  # no stage began
    assert not (tmp_path / "o").exists()


def test_an_out_name_too_long_is_refused_before_any_stage_line(tmp_path, capsys):
    out = tmp_path / ("a" * 240)
    assert main(["identify", "membrane", "--load", "L1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--out: the name" in err and "240 bytes" in err
    assert "simulating" not in err


def test_design_progress_says_something_at_least_every_interval():
    now = [0.0]
    lines: list[str] = []
    progress = DesignProgress("design", interval=5.0, heartbeat=False, clock=lambda: now[0], enabled=False)
    stages = (("model", 3), ("information", 40), ("criteria", 1), ("relaxation", 1), ("greedy", 20), ("swaps", 60))
    for stage, steps in stages:
        for k in range(steps):
            now[0] += 1.0  # one second per step: a line at least every 5 s
            progress(stage, (k + 1) / steps)
    progress.finish()
    lines = progress.lines
    assert [line for line in lines if "] " in line and "(" in line][0].startswith("[1/6] modes")
    assert sum(1 for line in lines if line.startswith("[6/6] swaps")) >= 60 // 5
    assert "about" in lines[-2]  # an estimate of what is left
    assert lines[-1] == "design: done in 2 min" or lines[-1].startswith("design: done in")
    # never more than 5 s of steps between two lines: 125 steps, at least one line per 5
    assert len(lines) >= 125 // 5


def test_design_progress_beats_within_one_long_call():
    """A stage that is one long call (the relaxation's solver) still gets a line every interval."""
    progress = DesignProgress("design", interval=0.05)
    try:
        progress("relaxation", 0.0)
        time.sleep(0.4)
    finally:
        progress.finish()
    beats = [line for line in progress.lines if line.startswith("[4/6] convex relaxation, running")]
    assert len(beats) >= 2
    n = len(progress.lines)
    time.sleep(0.15)
    assert len(progress.lines) == n  # finished: the timer is gone


def test_design_sensors_shows_its_stages_on_stderr(tmp_path, capsys):
    cands = "only-rects;rect=0.02:0.05:0.01:0.025;rect=0.08:0.11:0.045:0.06"
    args = ["design-sensors", "membrane", "--count", "2", "--candidates", cands, "--criterion", "a"]
    assert main([*args, "--nominal", "1", "--t-end", "0.1", "--no-plots", "--out", str(tmp_path / "d")]) == 0
    err = capsys.readouterr().err
    for stage in ("model", "information", "criteria", "relaxation", "greedy", "swaps"):
        assert f"] {stage}" in err or f"] {DesignProgress.LABELS[stage]}" in err, stage
    assert "design-sensors: 2 sensors, criterion a: done in" in err


@pytest.mark.slow
def test_the_shipped_dice_example_identifies(tmp_path, capsys):
    """examples/tunnel_dice.toml on its three DICe files: the steady fit of their mean field."""
    out = tmp_path / "dice"
    toml, frames = ROOT / "examples" / "tunnel_dice.toml", ROOT / "examples" / "data" / "tunnel_dice"
    assert main(["identify", str(toml), "--dic", str(frames), "--out", str(out), "--no-plots"]) == 0
    captured = capsys.readouterr()
    line = captured.out.strip().splitlines()[-1]
    assert line.startswith("full field (DIC), 3 frames x 800 points, steady fit of their mean: lift ")
    assert "N (1 sd)" in line and "s CPU" in line and "s wall" in line
    summary = json.loads((out / "summary.json").read_text())
    # the stand-in's lift (examples/make_tunnel_standin.py: 1.76 N), within the band
    assert abs(summary["lift_N"] - 1.76) < 2 * summary["lift_std_N"]
    assert 1.5 < summary["lift_N"] < 2.0
    warned = sum(1 for x in captured.err.splitlines() if ": warning: " in x)
    if warned:
        assert f"({warned} warning{'s' * (warned != 1)} above" in line
