"""Streaming identification: real-time iteration vs the batch MHE, bounded work and memory, the
row-by-row CSV reader and ``wingopt identify --follow`` / ``--data -`` with a writer process.

Truth on a finer mesh than the estimator's (no inverse crime); the estimators are not told the
noise level.
"""

import csv
import dataclasses
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from wingopt.errors import DataFileError, InputError
from wingopt.estimation.mhe import MHESettings, mhe_identify
from wingopt.estimation.streaming import StreamingEstimator, StreamSettings
from wingopt.estimation.streaming.rows import LinearRows, RtiNormalEquations
from wingopt.measurements.csv_stream import CsvRowParser
from wingopt.membrane import MembraneModel
from wingopt.problem import PROBLEMS_DIR
from wingopt.workflows.protocols import simulate_case

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def stream(est, meas, start=0, stop=None):
    out = []
    for k in range(start, meas.count if stop is None else stop):
        out.append(est.push(meas.t[k], meas.values[k]))
    return out


# -- the protocol on 25x13: streaming vs batch ---------------------------------------------------
@pytest.fixture(scope="module")
def protocol(membrane_problem, membrane_models):
    """L1, 1 %, truth 49x25, 1 s at 1 kHz; the estimator's model 25x13."""
    case = simulate_case(membrane_problem, "L1", 0.01, 0, (49, 25), t_end=1.0)
    return membrane_models[(25, 13)], case, dataclasses.replace(case.measurements, noise_std=None)


@pytest.fixture(scope="module")
def streamed(protocol):
    model, case, meas = protocol
    est = StreamingEstimator(model, StreamSettings())
    cpu = []
    out = []
    for k in range(meas.count):
        c = time.thread_time()
        out.append(est.push(meas.t[k], meas.values[k]))
        cpu.append(time.thread_time() - c)
    return est, out, np.array(cpu)


def test_stream_final_lift_matches_batch_mhe(protocol, streamed):
    model, case, meas = protocol
    est, out, _ = streamed
    batch = mhe_identify(model, meas)
    final = out[-1]
    # Issue 15: within 1 % of the batch MHE on the same record (measured: 1e-5).
    assert abs(final.lift / batch.lift[-1] - 1) < 0.01
    assert abs(final.lift / batch.lift[-1] - 1) < 1e-3
    assert abs(final.lift / case.true_lift - 1) < 0.015
    # Its band is the batch's (lambda integrated the same way), within 10 %.
    assert final.lift_std == pytest.approx(batch.lift_std[-1], rel=0.1)
    assert final.adequate and 0.8 < final.chi2_per_datum < 1.3
    # The noise level and lambda were chosen once by the batch's rules on the first windows.
    info = est.info()
    assert info["noise_source"] == "estimated from the data"
    assert info["lambda"] == pytest.approx(batch.regularization, rel=0.2)
    assert info["sign"]["determined"]


def test_stream_phases_and_startup_estimates(streamed, protocol):
    _, case, meas = protocol
    est, out, _ = streamed
    phases = [e.phase for e in out]
    assert phases[:19] == ["waiting"] * 19 and np.isnan(out[0].lift) and np.isinf(out[0].lift_std)
    assert phases[19] == "provisional" and phases.index("startup") == 399
    assert set(phases[400:]) == {"tracking"}
    # Before the start-up the estimate comes with a wider band, and the band covers the error
    # from the first window on.
    prov = out[250]
    assert prov.lift_std > 2 * out[-1].lift_std
    assert abs(prov.lift - case.true_lift) < 3 * prov.lift_std
    # The decayed initial states were marginalised: only the load (40 modal forces) is left.
    assert est._core.active.size == 40
    assert est.info()["normal_equations_drift"] < 1e-12


def test_stream_iterate_is_the_window_optimum(streamed):
    """The real-time iteration sits at the optimum of its window problem: more Gauss–Newton
    iterations with every row re-linearised move the lift by < 1e-5 (relative)."""
    est, out, _ = streamed
    core = est._core
    saved = (core.H.copy(), core.g.copy(), core.chi2, est.theta.copy(), core._J.copy(), core._z.copy())
    lift0 = out[-1].lift
    for _ in range(3):
        core.relinearize_all(est.theta)
        est._gauss_newton(trust=np.inf)
    lift1 = float(est._rows.lift_row @ est.theta)
    assert abs(lift1 / lift0 - 1) < 1e-5
    assert core.window_chi2_exact(est.theta) == pytest.approx(core.chi2, rel=1e-3)
    core.H, core.g, core.chi2, est.theta, core._J, core._z = saved


def test_stream_cost_per_sample(streamed):
    """Work per sample is bounded: the median tracking sample costs well under the 1 ms period
    (the p99 on one core is measured by benchmarks/bench_streaming.py)."""
    _, out, cpu = streamed
    tracking = cpu[np.array([e.phase == "tracking" for e in out])]
    # under the 1 ms period with room: 0.39-0.54 ms measured on this shared host (2x slower some weeks)
    assert np.median(tracking) < 0.8e-3


# -- small model: memory, missing data, adequacy, errors -----------------------------------------
@pytest.fixture(scope="module")
def small(membrane_problem):
    problem = membrane_problem.with_mesh((13, 7))
    model = MembraneModel.from_problem(problem)
    case = simulate_case(problem, "L1", 0.01, 3, (25, 13), t_end=0.5)
    return model, case, dataclasses.replace(case.measurements, noise_std=None)


SMALL = StreamSettings(mhe=MHESettings(window=100, modes=20), startup_windows=2.0)


def test_memory_and_work_do_not_grow(small):
    model, case, meas = small
    est = StreamingEstimator(model, SMALL)
    stream(est, meas)
    core = est._core
    arrays = {k: v.nbytes for k, v in vars(core).items() if isinstance(v, np.ndarray)}
    clean, sigma = case.trajectory.outputs[-1], case.measurements.noise_std
    rng = np.random.default_rng(5)
    t = meas.t[-1]
    for _ in range(3000):
        t += 1e-3
        e = est.push(t, clean + sigma * rng.standard_normal(clean.size))
    after = {k: v.nbytes for k, v in vars(core).items() if isinstance(v, np.ndarray)}
    assert after.keys() == arrays.keys() and all(after[k] <= arrays[k] for k in arrays)  # only shrinks
    assert core.active.size == 20  # every initial state has decayed: the load's modal forces are left
    assert core.size == core.window == 100 and core.absorbed == est.count - 100 - est.info()["origin_sample"]
    assert est._buf_t == [] and est._buf_y == []
    assert abs(e.lift / case.true_lift - 1) < 0.03 and e.adequate


def test_missing_samples_and_adequacy_flag(small):
    model, case, meas = small
    values = meas.values.copy()
    values[300:320, 1] = np.nan  # a sensor drops out
    values[330] = np.nan  # a whole row missing
    est = StreamingEstimator(model, SMALL)
    out = [est.push(t, y) for t, y in zip(meas.t[:331], values[:331])]
    assert est._core.n_data == 400 - 20 - 4  # the window holds samples 231..330
    out += [est.push(t, y) for t, y in zip(meas.t[331:], values[331:])]
    assert all(np.isfinite(e.lift) for e in out[20:])
    assert est._core.n_data == 400
    assert out[-1].adequate
    # A step in the data the constant load cannot explain (all stretches +30 %) is flagged.
    t = meas.t[-1]
    flags = []
    for _ in range(100):
        t += 1e-3
        flags.append(est.push(t, 1.3 * case.trajectory.outputs[-1]).adequate)
    assert not flags[-1] and est.last.chi2_per_datum > 10


def test_input_errors(small):
    model, _, meas = small
    with pytest.raises(InputError, match="only 'constant'"):
        StreamSettings(mhe=MHESettings(load_model="random_walk"))
    est = StreamingEstimator(model, SMALL)
    with pytest.raises(InputError, match="values for 4 sensors"):
        est.push(0.0, [0.1, 0.2])
    est.push(0.0, meas.values[0])
    est.push(0.001, meas.values[1])
    with pytest.raises(InputError, match="sample period"):
        est.push(0.0025, meas.values[2])
    with pytest.raises(InputError, match="initial_load"):
        StreamingEstimator(model, SMALL, initial_load=0.0)


def test_deactivate_is_a_marginalisation():
    """Dropping unknowns by the Schur complement leaves the estimate of the others unchanged."""

    class Rows:
        p, dim, row_shape = 1, 5, (1,)

    rng = np.random.default_rng(0)
    A = rng.standard_normal((8, 5))
    H0, g0 = A.T @ A + np.eye(5), rng.standard_normal(5)
    core = RtiNormalEquations(Rows(), 3, H0, g0, np.ones(5))
    full = np.linalg.solve(core.hessian(), core.g)
    core.deactivate(np.array([0, 2]))
    assert core.active.tolist() == [1, 3, 4]
    assert np.allclose(np.linalg.solve(core.hessian(), core.g), full[[1, 3, 4]], rtol=1e-12)


def test_linear_rows_match_the_batch_window_basis(small):
    model, _, _ = small
    from wingopt.estimation.mhe import MovingHorizonEstimator

    red = MovingHorizonEstimator(model, MHESettings(modes=20)).reduced
    rows = LinearRows(red)
    seq = np.array([rows.row_data() for _ in range(50)])
    basis = red.window(50, 1)
    theta = np.random.default_rng(1).standard_normal(3 * red.m)
    Y, J = rows.evaluate(theta, seq)
    Yb, Jb = red.outputs_and_jacobian(basis, theta)
    assert np.allclose(Y, Yb, rtol=1e-12, atol=1e-14 * np.abs(Yb).max())
    assert np.allclose(J, Jb, rtol=1e-12, atol=1e-14 * np.abs(Jb).max())


# -- the row-by-row CSV reader ---------------------------------------------------------------------
def test_csv_row_parser_gaps_end_marker_and_errors():
    p = CsvRowParser(("S1", "S2"), "live.csv")
    assert p.feed("# comment") == [] and p.feed("t,S2,S1,x") == []
    assert p.ignored_columns == ["x"]
    ((t, v),) = p.feed("0.000,0.2,0.1,7")
    assert t == 0 and v.tolist() == [0.1, 0.2]
    assert len(p.feed("0.001,0.2,0.1,7")) == 1
    rows = p.feed("0.004,,0.1,7")  # two samples missing in between, S2 missing
    assert [round(r[0], 6) for r in rows] == [0.002, 0.003, 0.004] and np.isnan(rows[0][1]).all()
    assert p.gap_rows == 2 and p.missing_rows == 1
    with pytest.raises(DataFileError, match="live.csv:6: irregular sampling"):
        p.feed("0.0055,0.2,0.1,7")
    with pytest.raises(DataFileError, match="expected the dimensionless stretch"):
        p.feed("0.005,20,0.1,7")
    p.feed("# END ")
    assert p.ended
    with pytest.raises(DataFileError, match="after the end marker"):
        p.feed("0.006,0.2,0.1,7")
    with pytest.raises(DataFileError, match="missing sensor column"):
        CsvRowParser(("S1", "S2")).feed("t,S1")


# -- the command line: a writer process appends while wingopt follows --------------------------
@pytest.fixture(scope="module")
def small_cli(tmp_path_factory, membrane_problem):
    d = tmp_path_factory.mktemp("follow")
    src = (PROBLEMS_DIR / "membrane.toml").read_text().replace("nodes = [25, 13]", "nodes = [13, 7]")
    (d / "small.toml").write_text(src)
    case = simulate_case(membrane_problem.with_mesh((13, 7)), "L1", 0.01, 2, (25, 13), t_end=0.5)
    m = case.measurements
    lines = [",".join(["t", *m.sensor_names])]
    lines += [f"{t:.6f}," + ",".join(f"{v:.8e}" for v in y) for t, y in zip(m.t, m.values)]
    return d, lines, m.t


WRITER = """
import sys, time
src, dst, every, end = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4] == "1"
lines = open(src).read().splitlines()
with open(dst, "w") as fh:
    for i, line in enumerate(lines):
        fh.write(line + "\\n")
        if i % every == 0:
            fh.flush()
            time.sleep(0.01)
    if end:
        fh.write("# end\\n")
"""

CLI = [sys.executable, "-m", "wingopt", "identify"]
FAST = ["--model", "linear", "--window", "100", "--modes", "20", "--print-every", "50"]  # the linear stream


def _env():
    return {**os.environ, "PYTHONPATH": ROOT, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


def _lift_rows(out):
    with open(out / "lift.csv") as fh:
        return list(csv.DictReader(fh))


def test_follow_with_writer_process_until_end_marker(small_cli, tmp_path):
    d, lines, t = small_cli
    (tmp_path / "all.csv").write_text("\n".join(lines) + "\n")
    live, out = tmp_path / "live.csv", tmp_path / "out"
    # The follower starts first and waits for the file; the writer appends in bursts of 25 rows.
    follower = subprocess.Popen(
        CLI + [str(d / "small.toml"), "--follow", str(live), "--out", str(out), *FAST],
        env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
    )  # fmt: skip
    writer = subprocess.run([sys.executable, "-c", WRITER, str(tmp_path / "all.csv"), str(live), "25", "1"])
    assert writer.returncode == 0
    stdout, stderr = follower.communicate(timeout=120)
    assert follower.returncode == 0, stderr
    rows = _lift_rows(out)
    # Every row's estimate, once, in order, none twice.
    assert [float(r["t"]) for r in rows] == pytest.approx(t.tolist(), abs=1e-9)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stopped"] == "end marker" and summary["samples"] == t.size == summary["rows_written"]
    assert summary["estimator"]["phase"] == "tracking"
    assert summary["status"] == ("converged" if summary["adequate"] else "misfit")
    assert float(rows[-1]["lift_N"]) == pytest.approx(summary["lift_N"], rel=1e-9)
    assert summary["warnings"] == [] or all(isinstance(w, str) for w in summary["warnings"])
    printed = stdout.strip().splitlines()
    assert printed[0].startswith("t,lift_N") and len(printed) == 1 + (t.size + 49) // 50


def test_follow_sigterm_stops_cleanly(small_cli, tmp_path):
    d, lines, _ = small_cli
    live, out = tmp_path / "live.csv", tmp_path / "out"
    live.write_text("\n".join(lines[:301]) + "\n")  # 300 rows, no end marker: the follower waits
    follower = subprocess.Popen(
        CLI + [str(d / "small.toml"), "--follow", str(live), "--out", str(out), *FAST],
        env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
    )  # fmt: skip
    deadline = time.monotonic() + 90
    seen = 0
    while time.monotonic() < deadline and seen < 300:  # wait until all 300 estimates are written
        tmp = [p for p in tmp_path.iterdir() if p.name.startswith(".out.tmp-")]
        if tmp and (tmp[0] / "lift.csv").exists():
            seen = len((tmp[0] / "lift.csv").read_text().splitlines()) - 1
        time.sleep(0.1)
    assert seen == 300
    with open(live, "a") as fh:  # a half-written line is not parsed
        fh.write("0.9,0.01")
    follower.send_signal(signal.SIGTERM)
    _, stderr = follower.communicate(timeout=60)
    assert follower.returncode == 0, stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stopped"] == "SIGTERM" and summary["samples"] == 300 == len(_lift_rows(out))
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out.")]


def test_stdin_stream_and_idle_timeout(small_cli, tmp_path):
    d, lines, t = small_cli
    out = tmp_path / "out"
    run = subprocess.run(
        CLI + [str(d / "small.toml"), "--data", "-", "--out", str(out), *FAST],
        input="\n".join(lines[:151]), env=_env(), capture_output=True, text=True, timeout=120, cwd=tmp_path,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stopped"] == "end of input" and summary["samples"] == 150
    assert any("provisional" in w for w in summary["warnings"])  # ended before the start-up (at 200 rows)
    assert summary["status"] == "not_converged"
    # --follow on a file that stops growing: the idle timeout ends the run.
    live = tmp_path / "idle.csv"
    live.write_text("\n".join(lines[:51]) + "\n")
    run = subprocess.run(
        CLI + [str(d / "small.toml"), "--follow", str(live), "--idle-timeout", "1", "--out", str(tmp_path / "o2")],
        env=_env(), capture_output=True, text=True, timeout=120, cwd=tmp_path,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    summary = json.loads((tmp_path / "o2" / "summary.json").read_text())
    assert summary["stopped"].startswith("idle") and summary["samples"] == 50


@pytest.mark.slow
def test_rss_growth_over_ten_minutes_of_stream(protocol, streamed):
    """Resident memory does not grow (the full hour: benchmarks/bench_streaming.py)."""
    model, case, meas = protocol
    est = StreamingEstimator(model, StreamSettings())
    stream(est, meas)

    def rss():
        with open("/proc/self/status") as fh:
            return next(int(x.split()[1]) for x in fh if x.startswith("VmRSS")) / 1024

    r0 = rss()
    clean, sigma = case.trajectory.outputs[-1], case.measurements.noise_std
    rng = np.random.default_rng(9)
    t = meas.t[-1]
    for _ in range(600):
        Y = clean + sigma * rng.standard_normal((1000, clean.size))
        for y in Y:
            t += 1e-3
            est.push(t, y)
    assert rss() - r0 < 10.0


def test_bad_row_keeps_the_record_and_exits_2(small_cli, tmp_path):
    from wingopt.cli import main

    d, lines, _ = small_cli
    bad = lines[:100] + ["0.0995," + lines[100].split(",", 1)[1]] + lines[100:]  # an off-grid time
    live = tmp_path / "bad.csv"
    live.write_text("\n".join(bad) + "\n")
    out = tmp_path / "out"
    assert main(["identify", str(d / "small.toml"), "--follow", str(live), "--out", str(out), *FAST]) == 2
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stopped"].startswith("bad input:") and "irregular sampling" in summary["stopped"]
    assert summary["samples"] == 99 == len(_lift_rows(out))
    assert main(["identify", str(d / "small.toml"), "--data", "-", "--method", "jekf", "--out", str(out)]) == 2
    assert main(["identify", str(d / "small.toml"), "--follow", str(live), "--print-every", "0", "--out", "x"]) == 2
