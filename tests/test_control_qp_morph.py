"""Morphing QP in the closed-loop harness (full-order plant): the Must-show items of issue 4.

Fast checks on 7x31; the 13x61 headline is ``@pytest.mark.slow``.
"""

import numpy as np
import pytest

from wingopt.optim import default_backend
from wingopt.plate import PlateModel
from wingopt.problem import load_problem
from wingopt.workflows.morph import morph

VMIN, VMAX = -500.0, 1500.0
SHAPES = ("twist", "camber", "bending")


@pytest.fixture(scope="module")
def problem():
    return load_problem("plate")


def _runs(problem, nodes):
    model = PlateModel.from_problem(problem, nodes)
    out = {}
    for shape in SHAPES:
        out[shape] = {
            "qp": morph(problem, shape, "qp", vmin=VMIN, vmax=VMAX, model=model),
            "qp-open": morph(problem, shape, "qp", vmin=VMIN, vmax=VMAX, model=model, mode="open-loop"),
            "lqr-sat": morph(problem, shape, "lqr", vmin=VMIN, vmax=VMAX, model=model),
        }
    return out


@pytest.fixture(scope="module")
def runs(problem):
    return _runs(problem, (7, 31))


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("method", ["qp", "qp-open"])
def test_voltage_limits_hold_in_the_applied_inputs(runs, shape, method):
    """Must show: within 1e-6 V of -500/+1500 V, as requested by the controller (before the harness's clip)."""
    cl = runs[shape][method].closed_loop
    for u in (cl.u_requested, cl.u):
        assert u.min() >= VMIN - 1e-6 and u.max() <= VMAX + 1e-6
    # The limits are reached (the QP uses the range it has) and the slew bound holds.
    assert cl.u_requested.max() > VMAX - 1.0 and cl.u_requested.min() < VMIN + 1.0
    slew = runs[shape][method].extras["settings"]["slew_rate"] * cl.period
    steps = np.abs(np.diff(np.vstack([np.zeros(cl.u.shape[1]), cl.u]), axis=0))
    assert steps.max() <= slew + 1e-6


@pytest.mark.parametrize("shape", SHAPES)
def test_closed_loop_qp_beats_saturated_lqr_and_reaches_the_static_optimum(runs, shape):
    """Must show: final shape error below saturated LQR's and within 2 % of the static optimum's."""
    qp, lqr = runs[shape]["qp"], runs[shape]["lqr-sat"]
    err, static = qp.closed_loop.final_shape_error, qp.extras["static_optimum_error"]
    assert err < lqr.closed_loop.final_shape_error
    assert abs(err - static) <= 0.02 * static
    # Nothing can hold a better shape within the limits than the static optimum (up to residual motion).
    assert err >= 0.98 * static


@pytest.mark.parametrize("shape", SHAPES)
def test_open_loop_qp_reaches_the_static_optimum_too(runs, shape):
    qp = runs[shape]["qp-open"]
    err, static = qp.closed_loop.final_shape_error, qp.extras["static_optimum_error"]
    assert abs(err - static) <= 0.02 * static
    assert qp.extras["qp_solves"] == 1 and qp.extras["qp_horizon"] == 200


def test_extras_report_the_qp_numbers(runs):
    ex = runs["twist"]["qp"].extras
    for key in ("static_optimum_error", "reduced_states", "qp_step_median_s", "qp_solver", "build_s"):
        assert key in ex
    assert ex["qp_solver"] == default_backend()
    assert ex["qp_formulation"] == ("condensed" if default_backend() == "daqp" else "sparse")
    assert ex["qp_solves"] == 200
    summary = runs["twist"]["qp"].summary()
    assert summary["static_optimum_error"] == ex["static_optimum_error"]


@pytest.mark.slow
def test_headline_13x61(problem):
    """The headline mesh: bounds, QP below saturated LQR and within 2 % of the static optimum."""
    runs = _runs(problem, (13, 61))
    for shape in SHAPES:
        qp, lqr = runs[shape]["qp"], runs[shape]["lqr-sat"]
        cl = qp.closed_loop
        assert cl.u_requested.min() >= VMIN - 1e-6 and cl.u_requested.max() <= VMAX + 1e-6
        err, static = cl.final_shape_error, qp.extras["static_optimum_error"]
        assert err < lqr.closed_loop.final_shape_error
        assert abs(err - static) <= 0.02 * static
        assert abs(runs[shape]["qp-open"].closed_loop.final_shape_error - static) <= 0.02 * static
