"""Progress you can see (issue 26): stage lines with a time estimate on stderr, piped or not; runs
estimated beyond the time limit refused in seconds unless --force; SIGTERM honoured within a second
with nothing left behind."""

from __future__ import annotations

import logging
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from wingopt import resources
from wingopt.errors import InputError
from wingopt.progress import Stages, fmt_duration

ROOT = Path(__file__).resolve().parents[1]


def _env() -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _cli(*args: str, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "wingopt", *args], env=_env(), cwd=ROOT, **kw)


class _Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_stage_lines_scale_the_a_priori_costs_by_the_time_taken(caplog):
    clock = _Clock()
    with caplog.at_level(logging.INFO, logger="wingopt.progress"):
        st = Stages([10.0, 10.0, 20.0], "job", seconds=True, clock=clock)
        st.start("one")
        clock.now += 30.0  # three times slower than its cost
        st.start("two")
        clock.now += 30.0
        st.start("three")
        clock.now += 60.0
        total = st.finish()
    assert st.lines == [
        "job: about 40 s",
        "[1/3] one (0 s so far, about 40 s left)",
        "[2/3] two (30 s so far, about 1.5 min left)",  # 30 s for a cost of 10: the other 30 take 90 s
        "[3/3] three (60 s so far, about 60 s left)",
        "job: done in 2 min",
    ]
    assert total == 120.0
    assert [r.getMessage() for r in caplog.records] == st.lines


def test_stages_done_out_of_order_and_disabled(caplog):
    clock = _Clock()
    with caplog.at_level(logging.INFO, logger="wingopt.progress"):
        st = Stages([1.0, 3.0], "tasks", clock=clock, enabled=False)
        clock.now += 6.0
        st.done(1, "b")
    assert caplog.records == []  # disabled: nothing logged, the lines still kept
    assert st.lines[-1] == "[1/2] done: b (6 s so far, about 2 s left)"
    assert fmt_duration(5400) == "1.5 h" and fmt_duration(3 * 86400) == "3 days"


def test_identify_piped_shows_stage_lines_on_stderr(tmp_path):
    """stderr a file (not a terminal): the stage lines are there, stdout keeps the result only."""
    err = tmp_path / "stderr.txt"
    with open(err, "w") as fh:
        p = _cli("identify", "membrane", "--load", "L1", "--t-end", "0.2", "--no-plots", "--out", str(tmp_path / "o"),
                 stdout=subprocess.PIPE, stderr=fh, text=True)  # fmt: skip
        out, _ = p.communicate(timeout=300)
    assert p.returncode == 0, err.read_text()
    lines = err.read_text().splitlines()
    assert "wingopt identify: simulating the linear truth of L1 on 49x25, 201 samples (the whole run: about" in lines[0]
    assert "wingopt identify: mhe estimator with the linear membrane on 201 samples of 4 sensors" in lines
    assert any(re.fullmatch(r"wingopt identify: writing the outputs \(the estimate took \d+ s\)", ln) for ln in lines)
    assert "simulating" not in out  # stage lines never on stdout


def test_quiet_hides_the_stage_lines(tmp_path):
    p = _cli("identify", "membrane", "--load", "L1", "--t-end", "0.1", "--no-plots", "-q", "--out",
             str(tmp_path / "o"), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    _, err = p.communicate(timeout=300)
    assert p.returncode == 0 and "simulating" not in err and "done in" not in err


def test_a_run_estimated_beyond_the_limit_is_refused_in_seconds_naming_the_option(tmp_path):
    """Refused in under 5 s of CPU (the interpreter's start and imports included; the wall time
    depends on the machine's load)."""
    p = _cli("morph", "plate", "--shape", "twist", "--mesh", "200x800", "--out", str(tmp_path / "m"),
             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    err = p.stderr.read()
    p.stdout.read()
    _, status, usage = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    assert usage.ru_utime + usage.ru_stime < 5.0
    assert p.returncode == 2
    assert err.count("\n") == 1
    assert "--mesh 200x800" in err and "156 days" in err and "limit of 1 day" in err and "--force" in err
    assert not (tmp_path / "m").exists()


def test_the_time_limit_is_lifted_by_long_runs_only():
    est = resources.estimate_morph((200, 800), 2.0, 0.01)
    assert est.seconds > resources.MAX_SECONDS
    with pytest.raises(InputError, match="longer than the limit of 1 day; give a smaller --mesh$"):
        resources.check(est, max_memory=1e15)
    with resources.long_runs(False, "--force"), pytest.raises(InputError, match="or --force to run it anyway"):
        resources.check(est, max_memory=1e15)
    with resources.long_runs():
        assert resources.check(est, max_memory=1e15) is est
    with pytest.raises(InputError, match="more than --max-memory"):  # memory is never forced
        with resources.long_runs():
            resources.check(est, max_memory=1e9)


def test_reduced_jekf_order_is_estimated_cheaper():
    full = resources.estimate_identify((25, 13), 1001, method="jekf-tuned")
    reduced = resources.estimate_identify((25, 13), 1001, method="jekf-tuned", jekf_modes=60)
    mhe = resources.estimate_identify((25, 13), 1001, method="mhe")
    assert mhe.seconds < reduced.seconds < full.seconds / 10
    assert reduced.knobs["JEKF covariance (dense)"] == "--jekf-order"


def _wait_for(pred, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.05)
    return False


@pytest.mark.skipif(not hasattr(os, "fork"), reason="the supervised child needs fork")
def test_sigterm_inside_a_long_solve_stops_morph_within_a_second(tmp_path):
    """A 100x300 plate (30600 dofs, estimated beyond the day's limit: --force): SIGTERM a few seconds
    in, inside the model build's sparse and dense solves, ends the run within a second."""
    out = tmp_path / "big"
    p = _cli("morph", "plate", "--shape", "twist", "--method", "lqr", "--mesh", "100x300", "--force", "--out",
             str(out), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    time.sleep(6.0)
    assert p.poll() is None, p.communicate()[1]
    t0 = time.perf_counter()
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=30)
    assert time.perf_counter() - t0 < 1.5
    assert p.returncode == 128 + signal.SIGTERM
    assert "terminated by SIGTERM; nothing written" in err
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.skipif(not hasattr(os, "fork"), reason="the supervised child needs fork")
def test_sigterm_mid_demo_leaves_no_partial_directory(tmp_path):
    """The demo writes into a temporary directory from its start: a SIGTERM removes it."""
    out = tmp_path / "demo"
    p = _cli("demo", "--quick", "--out", str(out), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert _wait_for(lambda: any(tmp_path.glob(".demo.tmp-*")) or p.poll() is not None, 120)
    time.sleep(1.0)
    assert p.poll() is None
    t0 = time.perf_counter()
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=30)
    assert time.perf_counter() - t0 < 1.5
    assert p.returncode == 143 and "nothing written" in err
    assert list(tmp_path.iterdir()) == []


def test_compare_piped_shows_a_line_per_finished_task_and_writes_the_overlay(tmp_path):
    """The study engine's stage lines (the plan with its estimate, one line per finished task, the
    end) on a piped stderr; the MHE–JEKF overlay among the outputs, the JEKF at 60 modes."""
    problem = tmp_path / "small.toml"
    problem.write_text((ROOT / "problems" / "membrane.toml").read_text().replace("nodes = [25, 13]", "nodes = [13, 7]"))
    err = tmp_path / "stderr.txt"
    with open(err, "w") as fh:
        p = _cli("compare", str(problem), "--loads", "L1", "--noise", "5", "--n-seeds", "1", "--methods",
                 "mhe,jekf-tuned", "--no-oracle", "--truth-mesh", "25x13", "--out", str(tmp_path / "cmp"),
                 stdout=subprocess.PIPE, stderr=fh, text=True)  # fmt: skip
        out, _ = p.communicate(timeout=600)
    assert p.returncode == 0, err.read_text()
    lines = err.read_text().splitlines()
    assert re.fullmatch(r"wingopt compare: compare, 2 tasks \(serial\): about \d+ s", lines[0])
    task = r"wingopt compare: \[(\d)/2\] done: (jekf_modes=60 )?load=L1 method=(mhe|jekf-tuned) noise=0.05 seed=0 "
    done = [re.match(task, ln).groups() for ln in lines if re.match(task, ln)]
    assert [d[0] for d in done] == ["1", "2"]
    assert {d[2]: d[1] for d in done} == {"mhe": None, "jekf-tuned": "jekf_modes=60 "}
    assert re.fullmatch(r"wingopt compare: compare, 2 tasks \(serial\): done in \d+ s", lines[-1])
    assert "| L1 | 5 % | mhe |" in out and "done:" not in out and "JEKF 60 modes" in out
    png = tmp_path / "cmp" / "overlay-L1.png"
    assert png.read_bytes()[:4] == b"\x89PNG" and "overlay-L1.png" in out


def test_a_killed_childs_temporaries_are_removed_and_an_earlier_result_put_back(tmp_path):
    from wingopt.cli.process import remove_own_temporaries

    out = tmp_path / "run"
    (tmp_path / ".run.tmp-4242-abc").mkdir()
    (tmp_path / ".run.tmp-4242-abc" / "summary.json").write_text("{}")
    (tmp_path / ".run.tmp-999-xyz").mkdir()  # another process's: kept
    old = tmp_path / ".run.old-4242"
    old.mkdir()
    (old / "summary.json").write_text('{"earlier": 1}')
    remove_own_temporaries(str(out), 4242)
    assert sorted(p.name for p in tmp_path.iterdir()) == [".run.tmp-999-xyz", "run"]
    assert (out / "summary.json").read_text() == '{"earlier": 1}'
