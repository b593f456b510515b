"""Issue 11 Must-show checks of the realistic estimator (slow: minutes each on a shared machine).

Truth: Berger membrane on 49x25 with 120 modes and 8 sub-steps per sample
(:func:`wingopt.workflows.protocols.simulate_case`, full-order Berger), the seed's protocol (1 cm bubble at rest,
1 s at 1 kHz, four default sensors, 1 % noise); estimator on 25x13 with 48 modes and 2 sub-steps,
reading the problem file (prestrain 0.05, damping x1). NOT the Föppl–von Kármán truth (not merged
yet): the Berger physics is shared, the mesh, modes and integration are not.
"""

import dataclasses
import functools

import numpy as np
import pytest

from wingopt.estimation.mhe import mhe_identify
from wingopt.estimation.mhe.model_check import check_mhe_result
from wingopt.estimation.records import RecordSettings, identify_record
from wingopt.membrane import MembraneModel, add_noise
from wingopt.membrane.loads import Gust
from wingopt.problem import load_problem
from wingopt.workflows.protocols import simulate_case
from wingopt.workflows.studies import load_field

pytestmark = pytest.mark.slow


@functools.cache
def _problem_model():
    problem = load_problem("membrane")
    return problem, MembraneModel.from_problem(problem)


@functools.cache
def _clean(load, nonlinear=True, prestrain=None, damping=1.0, gust=False):
    problem, _ = _problem_model()
    gust = Gust() if gust else None
    truth = "berger" if nonlinear else "linear"
    return simulate_case(problem, load, 0.0, None, truth=truth, prestrain=prestrain, damping=damping, gust=gust)


def _run(load, seed=0, noise=0.01, estimator="realistic", settings=None, **truth):
    clean = _clean(load, **truth)
    noisy, _ = add_noise(clean.trajectory.outputs, noise, seed)
    meas = dataclasses.replace(clean.measurements, values=noisy, noise_std=None)
    _, model = _problem_model()
    if estimator == "realistic":
        res = identify_record(model, meas, settings)
    else:
        res = check_mhe_result(model, meas, mhe_identify(model, meas))
    lift_err = (res.lift[-1] - clean.lift_history[-1]) / clean.true_absolute_load
    return clean, res, float(lift_err), clean.load_error(load_field(res, model))


@pytest.mark.parametrize("load", ["L1", "L2", "LE"])
def test_lift_within_3_percent_on_nonlinear_truth_and_field_error_ratio(load):
    _, res, lift_err, field = _run(load)
    assert abs(lift_err) < 0.03
    assert res.info["model_adequate"]
    _, _, _, lin_field = _run(load, nonlinear=False)
    assert field <= 1.5 * lin_field  # measured 0.110/0.091, 0.076/0.133, 0.053/0.125


@pytest.mark.parametrize("factor", [0.8, 1.2])
def test_prestrain_off_and_damping_x2(factor):
    e0 = 0.05
    prestrain = (factor * e0, (2 - factor) * e0)
    free = RecordSettings(free=("prestrain_x", "prestrain_y", "damping"))  # the damping freed too
    clean, res, lift_err, _ = _run("L1", prestrain=prestrain, damping=2.0, settings=free)
    assert abs(lift_err) < 0.03
    est, std = res.info["parameters"], res.info["parameters_std"]
    # the first mode's tension, Tx kx1 + Ty ky1 ~ (1 + 4 nu) ex + (4 + nu) ey, is what the record fixes:
    # measured -0.8 % (factor 0.8) and -0.8 % (1.2)
    nu = 0.36
    comb = lambda ex, ey: (1 + 4 * nu) * ex + (4 + nu) * ey  # noqa: E731
    assert abs(comb(est["prestrain_x"], est["prestrain_y"]) / comb(*prestrain) - 1) < 0.03
    for k, true in zip(("prestrain_x", "prestrain_y"), prestrain):
        # The split is weakly determined but honest: measured 0.8: -10 %, +2.6 % (0.7, 0.5 sigma);
        # 1.2: -21 %, +16 % (2.0, 1.8 sigma). (Until the LM stopped on the Newton decrement, 0.8
        # came out -2.9 %, +0.1 %: a stop short of the minimum along this valley, not information.)
        assert abs(est[k] - true) < 3 * std[k]
    assert abs(est["damping"] / 2.0 - 1) < 0.03  # measured -0.7 %, -0.1 %
    assert res.info["model_adequate"]


def test_gust_is_followed():
    clean, res, _, _ = _run("L1", gust=True)
    assert res.info["load_model"] == "gust"
    k = np.searchsorted(res.t, 0.1)
    true = clean.lift_history[np.searchsorted(clean.trajectory.t, res.t)]
    rms = np.sqrt(np.mean((res.lift[k:] - true[k:]) ** 2)) / true[0]
    assert rms <= 0.03
    assert abs(res.lift.max() / true.max() - 1) <= 0.05
    assert abs(res.t[np.argmax(res.lift)] - res.t[np.argmax(true)]) <= 0.010


def test_linear_model_on_nonlinear_data_is_flagged_and_its_band_covers():
    clean, res, lift_err, _ = _run("LE", estimator="mhe")
    assert not res.info["model_adequate"]
    assert res.info["warnings"]
    assert abs(res.lift[-1] - clean.lift_history[-1]) <= res.lift_std[-1]


def test_lift_band_coverage_over_20_seeds():
    """The band covers every seed's error, and its noise part is the scatter of the answers (issue 31).

    The band is not a noise band, so it is not asked to cover 68 % of the seeds. Four interior
    sensors cannot tell whether the pressure reaches the frame: the frame prior fits these records
    as well (chi-square 2-9 lower) with a lift 4-19 % higher (seeds 0, 1, 3 run to the end: 0.826,
    0.838, 0.959 N for a true 0.794 N), and :func:`~wingopt.estimation.core.frame_check.span_other`
    adds the difference to the band (0.015-0.074 N over seeds 0-5): an ambiguity of the load's form
    common to every draw, which a band must cover and noise seeds cannot show. Measured parts of the
    band before that term (``info["lift_band_parts"]``): noise 0.009-0.011 N, prior 0.011-0.013 N
    (the load shapes and parameters the data leave to their prior: for one load, a bias common to all
    draws), no misfit inflation; the answers scatter by 0.009 N (seeds 0-5). So the check is that
    the band covers every error, and that the noise part matches the answers' scatter about their
    mean (its sampling error over 20 seeds is about 16 %).
    """
    lifts, noise, covered = [], [], []
    for seed in range(20):
        clean, res, _, _ = _run("L1", seed=seed)
        lifts.append(float(res.lift[-1]))
        noise.append(res.info["lift_band_parts"]["noise_N"])
        covered.append(abs(res.lift[-1] - clean.lift_history[-1]) <= res.lift_std[-1])
    assert all(covered)
    ratio = np.std(lifts, ddof=1) / np.sqrt(np.mean(np.square(noise)))
    assert 0.6 < ratio < 1.5, ratio
