"""Records made as a lab makes them (issue 32): a gust after the release, the frame prior's short
start on a gust record, BLAS-thread independence.

Truth for the studies: the full-order FvK membrane on 49x25 (the estimator's is 25x13), prestrains
(0.052, 0.048) and damping x1.05 where the problem file says 0.05 and 1, 1 % noise, the noise level
estimated from the data. Nothing is tuned on these records' loads.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from wingopt.estimation.core.load_model import GustAmplitude, LoadShapes
from wingopt.estimation.core.record_problem import ParameterPrior, RecordProblem
from wingopt.estimation.core.start import SCAN_S, short_start
from wingopt.estimation.records import RecordSettings, identify_record
from wingopt.estimation.steady.estimator import is_steady, mean_moves
from wingopt.membrane import MembraneModel, add_noise, bubble, load_case
from wingopt.membrane.loads import Gust
from wingopt.membrane.modal.berger import BergerModal
from wingopt.problem import load_problem
from wingopt.workflows.protocols import simulate_case

DATA = Path(__file__).parent / "data"
TRUTH = {"truth": "fvk", "prestrain": (0.052, 0.048), "damping": 1.05, "tell_noise": False}


@pytest.fixture(scope="module")
def model():
    return MembraneModel.from_problem(load_problem("membrane"))


# -- routing: a moving mean is not steady ------------------------------------------------------------------
def _release_then_gust(gust: Gust | None, n: int = 1000, seed: int = 0) -> np.ndarray:
    """Four sensors about ``p^(2/3)`` of a load with a release's ringing (18x the noise at first, as
    the protocol's bubble under L1 on FvK truth) and ``gust``'s load factor."""
    t = np.arange(n) / 1000.0
    factor = np.ones(n) if gust is None else gust.factor(t)
    ring = 0.08 * np.exp(-t / 0.03) * np.cos(2 * np.pi * 160 * t)
    y = (factor ** (2 / 3) + ring)[:, None] * np.array([1.0, 0.8, 1.2, 0.9])[None, :]
    return y + 0.005 * np.random.default_rng(seed).standard_normal(y.shape)


@pytest.mark.parametrize("gust", [Gust(), Gust(0.15, 0.15, 0.2), Gust(0.7, 0.2, 0.15)])
def test_a_gust_after_the_release_is_not_steady(gust):
    """The old test compared the first tenth with the second half: the gust in the second half hid the
    release's ringing and the record went to the steady route (-75 %, 18 bands, "adequate")."""
    assert not is_steady(_release_then_gust(gust))
    # the gust alone (no release) moves the windows' means: not steady either
    y = _release_then_gust(gust)
    y[:100] = y[100:200]
    assert not is_steady(y)


def test_a_drift_is_not_steady_and_buffeting_is():
    t = np.arange(1000) / 1000.0
    drift = (1.0 + 0.3 * t)[:, None] * np.ones((1, 4)) + 0.005 * np.random.default_rng(1).standard_normal((1000, 4))
    assert not is_steady(drift)
    for name in ("buffeting_e040_300Hz.npz", "buffeting_e060_300Hz.npz"):
        d = np.load(DATA / name)
        for seed in range(3):
            y, _ = add_noise(d["outputs"], 0.02, seed)
            assert is_steady(y), (name, seed)


def test_mean_moves_measures_the_largest_window_move():
    eps = np.zeros(1000)
    assert mean_moves(eps) == (False, 0.0)
    eps[400:500] = 0.3  # one window at +30 % of the load
    moved, move = mean_moves(eps)
    assert moved and move == pytest.approx(0.3)
    moved, move = mean_moves(0.01 * np.random.default_rng(0).standard_normal(1000))
    assert not moved and move < 0.01


# -- the crash: the frame prior's short start on a gust problem ----------------------------------------
def _gust_problem(model, seconds=0.7):
    bm = BergerModal.build(model, 10, substeps=2)
    pr = model.problem
    n = int(round(seconds * 1000))
    f = model.project(load_case("L2", pr.width, pr.height))
    forces = np.broadcast_to(bm.input_matrix @ f, (n - 1, bm.m))
    Q = bm.simulate(bm.to_modal(model.project(bubble(pr.width, pr.height))), np.zeros(bm.m), forces, 0.05, 0.05)
    t = np.arange(n) * 1e-3
    prior = ParameterPrior((0.05, 0.05), ("prestrain_x", "prestrain_y", "damping"))
    x_mean = np.concatenate([Q[0], np.zeros(bm.m)])
    shapes, gust = LoadShapes.build(model, 6), GustAmplitude(knot_s=0.01)
    x_std = np.abs(x_mean) + 1e-5
    return RecordProblem(bm, shapes, t, bm.outputs(Q), np.full(4, 1e-4), prior, x_mean, x_std, gust, True, 6)


def test_short_start_of_a_gust_problem_keeps_the_whole_records_unknowns(model):
    """The frame prior's fit of a gust record starts with :func:`short_start`, whose short record
    has fewer gust knots: it crashed ("matmul ... size 153 is different from 83")."""
    rp = _gust_problem(model)
    n = int(np.searchsorted(rp.t, rp.t[0] + SCAN_S, side="right"))
    short = dataclasses.replace(rp, t=rp.t[:n], y=rp.y[:n])
    assert short.dim < rp.dim  # the cause: knots over each problem's own samples
    theta0 = np.zeros(rp.dim)
    kn = rp.gust.knots(rp.t)
    theta0[rp.slices["g"]] = 0.1 + 0.2 * kn  # a linear amplitude: read at any knots exactly
    theta = short_start(rp, theta0)
    assert theta.shape == (rp.dim,) and np.all(np.isfinite(theta))
    cost0 = rp.residuals(theta0)[0] @ rp.residuals(theta0)[0]
    cost1 = rp.residuals(theta)[0] @ rp.residuals(theta)[0]
    assert cost1 < cost0
    beyond = kn > rp.t[n - 1] + 1e-9
    assert np.array_equal(theta[rp.slices["g"]][beyond], theta0[rp.slices["g"]][beyond])


# -- must show: gust records on FvK truth ---------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("gust", [Gust(), Gust(0.15, 0.15, 0.2), Gust(0.7, 0.2, 0.15)])
def test_must_show_gust_after_the_release(model, gust):
    """L1 with a 1-cos gust on the release transient (+60 % at 0.5 s; +40 % at 0.225 s, inside the
    ringing; +30 % at 0.8 s): the transient route's gust model. Measured: lift -1.0 %, -1.5 %,
    -1.4 % (bands 1.7-3.1 %), lift-history RMS error 1.6 %, 2.1 %, 1.9 % of the steady lift; the
    old routing read +60 % at 0.5 s -75 % (18 bands), "adequate". The same answer and status with
    one and two BLAS threads (the frame prior's shapes came out of LAPACK with another sign or
    basis: 3 % of the band)."""
    from threadpoolctl import threadpool_limits

    rec = simulate_case(model.problem, "L1", 0.01, 0, (49, 25), 1.0, gust=gust, **TRUTH)
    assert not is_steady(rec.measurements.values)
    s = RecordSettings(membrane_model="fvk")
    out = []
    for threads in (1, 2):
        with threadpool_limits(limits=threads, user_api="blas"):
            out.append(identify_record(model, rec.measurements, s))
    res = out[0]
    true = rec.true_lift
    assert res.method == "realistic" and res.info["load_model"] == "gust"
    assert abs(res.lift[-1] - true) / true < 0.05
    assert np.sqrt(np.mean((res.lift - rec.lift_history) ** 2)) / true < 0.05
    other = out[1]
    assert np.allclose(other.lift, res.lift, rtol=1e-6, atol=0) and np.allclose(other.lift_std, res.lift_std, rtol=1e-6)
    assert other.info["converged"] == res.info["converged"]
    assert other.info["model_adequate"] == res.info["model_adequate"]
    assert other.info["warnings"] == res.info["warnings"]


# -- time stamps as loggers write them ------------------------------------------------------------------------
STANDIN = Path(__file__).parent.parent / "examples" / "data" / "tunnel_300Hz.csv"


def _write(path, t, values, names, digits=4):
    with open(path, "w") as fh:
        fh.write("t," + ",".join(names) + "\n")
        for tk, row in zip(t, values):
            fh.write(f"{tk:.{digits}f}," + ",".join("" if np.isnan(v) else repr(float(v)) for v in row) + "\n")


def test_uniform_clock_reads_rounded_and_jittered_stamps_and_refuses_more():
    from wingopt.measurements.clock import IrregularSampling, uniform_clock

    t = np.arange(600) / 300.0
    rng = np.random.default_rng(0)
    exact = uniform_clock(t)
    assert not exact.jittered and exact.dt == pytest.approx(1 / 300, rel=1e-12)
    logged = uniform_clock(np.round(t + rng.uniform(-5e-5, 5e-5, t.size), 4))  # 0.1 ms, +-0.05 ms
    assert logged.jittered and logged.dt == pytest.approx(1 / 300, rel=1e-5)
    assert 0.015 < logged.jitter < 0.031  # 0.05 ms rounding + 0.05 ms jitter, of 3.33 ms
    gap = uniform_clock(np.delete(t, [100, 101]) + rng.uniform(-2e-4, 2e-4, t.size - 2))  # 6 % jitter, a gap
    assert gap.count == 600 and list(gap.index[99:101]) == [99, 102]
    with pytest.raises(IrregularSampling, match="irregular sampling"):
        uniform_clock(t + rng.uniform(-0.2, 0.2, t.size) / 300)  # 20 % of a step


def test_logger_stamps_read_as_the_uniform_clock_with_the_same_answer(model, tmp_path):
    """The stand-in's rows with stamps rounded to 0.1 ms and +-0.05 ms jitter were refused
    ("irregular sampling (step 0.0032 s, typical 0.0033 s)"); read as the fitted clock they give the
    exact stamps' answer (measured 1.763260 and 1.763265 N: 3e-6 relative), and the clock is said."""
    from wingopt.measurements import read_measurements

    names = model.problem.sensor_names
    exact, _ = read_measurements(STANDIN, names)
    rng = np.random.default_rng(3)
    path = tmp_path / "logger.csv"
    _write(path, np.round(exact.t + rng.uniform(-5e-5, 5e-5, exact.count), 4), exact.values, names)
    logged, report = read_measurements(path, names)
    assert report.as_dict()["clock"]["max_deviation_steps"] < 0.05
    assert np.abs(logged.t - exact.t).max() < 1e-5 and np.array_equal(logged.values, exact.values, equal_nan=True)
    s = RecordSettings(membrane_model="fvk")
    a, b = identify_record(model, exact, s), identify_record(model, logged, s)
    assert b.reported_lift[0] == pytest.approx(a.reported_lift[0], rel=1e-4)
    assert b.reported_lift[1] == pytest.approx(a.reported_lift[1], rel=1e-3)


def test_arrays_pass_the_csv_readers_clock_checks(model):
    """An array whose time column jitters by 20 % passed without a word where the same rows as a CSV
    were refused; 3 % is read as the clock and said in the data checks."""
    from wingopt.errors import InputError
    from wingopt.estimation.core.sanity import as_measurements, record_checks
    from wingopt.measurements import Measurements

    names = model.problem.sensor_names
    rng = np.random.default_rng(1)
    t = np.arange(200) / 1000.0
    y = 0.01 + 1e-4 * rng.standard_normal((200, 4))
    with pytest.raises(InputError, match=r"array: row \d+: irregular sampling"):
        as_measurements(np.column_stack([t + rng.uniform(-2e-4, 2e-4, t.size), y]), names)
    with pytest.raises(InputError, match="irregular sampling"):
        as_measurements(Measurements(t + rng.uniform(-2e-4, 2e-4, t.size), y, names), names)
    meas = as_measurements(np.column_stack([t + rng.uniform(-3e-5, 3e-5, t.size), y]), names)
    assert meas.clock is not None and np.allclose(np.diff(meas.t), meas.clock["dt_s"], rtol=1e-9)
    assert any("time stamps jitter" in w for w in record_checks(model, meas, 200.0))
    # a gap of two samples in an array: filled with missing rows, as the CSV reader does
    gapped = as_measurements(np.column_stack([np.delete(t, [50, 51]), np.delete(y, [50, 51], axis=0)]), names)
    assert gapped.count == 200 and np.isnan(gapped.values[50:52]).all()


# -- streams that never stop -------------------------------------------------------------------------------------
def _small_stream(fvk_short_record):
    from wingopt.estimation.streaming.nonlinear import NonlinearStreamingEstimator
    from wingopt.estimation.streaming.types import NonlinearStreamSettings

    model, meas = fvk_short_record
    s = NonlinearStreamSettings(membrane_model="fvk", modes=12, cubic_modes=6, shapes=6, state_modes=6, startup_s=0.1)
    return NonlinearStreamingEstimator(model, s), meas


@pytest.mark.parametrize("failure", ["diverged", "nan covariance"])
def test_a_filter_failure_is_recovered_and_the_stream_runs_to_its_end(fvk_short_record, failure):
    """A diverged state or an innovation covariance no repair makes positive definite stopped the
    stream ("LinAlgError: innovation covariance not positive definite", L2 on FvK truth after 19
    samples); now the filter is reset from the batch fit of its latest samples, with a warning."""
    est, meas = _small_stream(fvk_short_record)
    n = meas.count
    for k in range(n):
        if k == 2 * n // 3:
            assert est.phase == "tracking"
            if failure == "diverged":
                est.x[: est.m] = 1e9
            else:
                est.Sigma[:] = np.nan
        e = est.push(meas.t[k], meas.values[k])
    assert est.count == n and np.isfinite(e.lift) and np.isfinite(e.lift_std) and e.phase == "tracking"
    info = est.info()
    assert info["recovery_count"] >= 1 and info["recoveries"][0]["sample"] == 2 * n // 3
    assert "reset" in info["recoveries"][0] and any("failed numerically" in w for w in info["warnings"])


def test_a_failure_soon_after_a_reset_holds_the_last_healthy_answer(fvk_short_record):
    """A record the model cannot follow failed again right after each reset (fuzz #437: an L2 gust
    through an undeclared filter, a reset at every sample, 17 s each, and the last failure left a
    diverged state: no lift at the end). A second failure before the ring has refilled goes back to
    the last healthy state and holds it, flagged, to the end of the input."""
    est, meas = _small_stream(fvk_short_record)
    n = meas.count
    k1 = 2 * n // 3
    for k in range(n):
        if k in (k1, k1 + 3):
            est.x[: est.m] = 1e9
        e = est.push(meas.t[k], meas.values[k])
        if k == k1 + 2:
            healthy_lift = e.lift
    info = est.info()
    assert info["recovery_count"] == 2 and info["recoveries"][1]["reset"].startswith("held: failed again 3 samples")
    assert est._recovery.hold and np.isfinite(e.lift) and not e.adequate  # held, flagged
    assert e.lift == pytest.approx(healthy_lift, rel=1e-12)  # the answer before the failure, not the prior's
    assert "ended held at its last answer" in info["warnings"][0]


def test_a_provisional_failure_holds_the_prior_until_the_start_up(fvk_short_record):
    est, meas = _small_stream(fvk_short_record)
    for k in range(25):
        if k == 22:
            est.x[: est.m] = np.inf
        est.push(meas.t[k], meas.values[k])
    assert est.phase == "provisional" and est._recovery.hold and np.isfinite(est.x).all()
    for k in range(25, meas.count):
        e = est.push(meas.t[k], meas.values[k])
    assert e.phase == "tracking" and not est._recovery.hold and np.isfinite(e.lift)
    assert est.info()["recovery_count"] == 1


def test_the_batch_check_carries_the_priors_spread_and_flags_a_disagreeing_filter():
    from types import SimpleNamespace

    from wingopt.estimation.core.result import Estimate
    from wingopt.estimation.streaming.batch_check import BatchCheck

    info = {"frame_check": {"lift_spread": 0.03}, "load_prior": {"lift_spread": 0.04}}
    batch = SimpleNamespace(reported_lift=(0.75, 0.02), info=info)
    e = Estimate(999, 0.999, 0.71, 0.01, None, 1.0, True, "tracking")
    check = BatchCheck.of(batch, e, 1000)
    assert check.spread == pytest.approx(0.05)  # the two prior terms in quadrature
    w = check.widened(e)
    assert w.lift_std == pytest.approx(np.hypot(0.01, 0.05)) and w.adequate and check.agrees
    assert len(check.warnings()) == 1
    narrow = BatchCheck.of(SimpleNamespace(reported_lift=(0.80, 0.06), info={}), e, 1000)
    assert narrow.widened(e).lift_std == pytest.approx(0.06)  # never narrower than the batch's band
    far = BatchCheck.of(SimpleNamespace(reported_lift=(0.0, 0.01), info={}), e, 1000)
    assert far.gap_bands == pytest.approx(0.71 / np.hypot(0.01, 0.01)) and not far.agrees
    assert not far.widened(e).adequate and "bands from the whole-record batch fit" in far.warnings()[-1]


@pytest.mark.slow
@pytest.mark.parametrize("load", ["L1", "L2", "L3", "LE", "bump"])
def test_must_show_streams_reach_the_end_within_two_bands_or_warned(model, load):
    """The FvK EKF stream (``identify --data -``'s) on FvK truth, the initial shape declared or not.
    Measured (benchmarks/lab_records.py stream): every stream reaches its 1001st sample; without
    the shape each one's provisional filter diverges once at sample 19 and is recovered; final
    lift within 2 bands except L2 undeclared (+27 bands: its start-up fit misfits, warned and
    flagged by the batch check) and the bump (-2.6 and -3.7 bands, warned)."""
    from wingopt.estimation.options import IdentifyOptions
    from wingopt.estimation.registry import resolve
    from wingopt.estimation.runners import build
    from wingopt.membrane.loads import tunnel_load

    pr = model.problem
    pressure = tunnel_load("tunnel-bump", pr.width, pr.height) if load == "bump" else load
    rec = simulate_case(pr, pressure, 0.01, 0, (49, 25), 1.0, **TRUTH)
    for peak in (pr.identification.initial_deflection, 0.0):
        m = MembraneModel.from_problem(pr.with_identification(initial_deflection=peak))
        est = build(resolve(stream=True), m, IdentifyOptions(), keep=False)
        for t, y in zip(rec.measurements.t, rec.measurements.values):
            e = est.push(t, y)
        assert est.count == rec.measurements.count and np.isfinite(e.lift)
        last = est.last
        warned = est.info().get("warnings", []) or not last.adequate
        assert abs(last.lift - rec.true_lift) <= 2 * last.lift_std or warned, (load, peak)
