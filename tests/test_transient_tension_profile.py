"""The lift's profile check of the realistic estimator (``tension_profile``): a record without a
transient (the wing already loaded when the recording starts) holds little on the tension, and its
band is checked by the lift's profile likelihood; a bubble-start record is left to its Laplace band.
Truth: the FvK membrane on 33x17 (the estimator's mesh is 25x13), L1, 1 % noise."""

import numpy as np
import pytest

from wingopt.estimation.records import RecordSettings, identify_record
from wingopt.estimation.transient.tension_profile import MAX_WIDENING, TRIGGER
from wingopt.measurements.series import Measurements
from wingopt.membrane import MembraneModel
from wingopt.problem import load_problem
from wingopt.workflows.protocols import simulate_case


@pytest.fixture(scope="module")
def setup():
    problem = load_problem("membrane")
    model = MembraneModel.from_problem(problem)
    case = simulate_case(problem, "L1", 0.01, 0, (33, 17), 1.0, truth="fvk", tell_noise=False)
    return model, case


def test_a_bubble_start_record_keeps_its_laplace_band(setup):
    model, case = setup
    rec = case.measurements
    k = int(np.searchsorted(rec.t, 0.5))
    meas = Measurements(rec.t[:k], rec.values[:k], rec.sensor_names, None, "bubble start")
    res = identify_record(model, meas, RecordSettings(membrane_model="fvk"))
    tp = res.info["tension_profile"]
    assert not tp["computed"] and not tp["applied"] and tp["ratio"] < TRIGGER / 2  # the ringing fixes the tension
    assert not any("tension" in w for w in res.info["warnings"])


def test_a_record_without_a_transient_has_its_band_checked_by_the_lifts_profile(setup):
    """The last 0.5 s of the record (the transient over), forced through the transient route (``auto``
    routes it to the steady estimator, see below): the tension is nearly the prior's, the lift is
    refitted held at both ends of its band, and the band is the profile's (never narrower)."""
    model, case = setup
    rec = case.measurements
    k = int(np.searchsorted(rec.t, 0.5))
    meas = Measurements(rec.t[k:] - rec.t[k], rec.values[k:], rec.sensor_names, None, "steady")
    # run to convergence (stop_early=False: this flat valley stalls, and a stalled fit has no optimum to profile)
    # (and no work budget: the profile's refits after a 96-iteration fit would spend the default 160,
    # and a run the budget cut is not converged)
    settings = RecordSettings(
        membrane_model="fvk", max_iter=200, record="transient", stop_early=False, max_total_iter=10**6
    )
    res = identify_record(model, meas, settings)
    tp = res.info["tension_profile"]
    assert res.info["converged"] and tp["ratio"] > TRIGGER and tp["computed"]
    lift = float(res.lift[-1])
    # the Laplace band: the reported one without the frame prior's lift (frame_check.span_other) and the widening
    total, frame = float(res.lift_std[-1]), res.info["frame_check"].get("lift_spread", 0.0)
    band = np.sqrt(total**2 - frame**2) / (tp["widening"] if tp["applied"] else 1.0)
    # the refits hold the lift exactly at the band's ends, and cost more than the optimum
    assert tp["lifts_N"] == pytest.approx([lift - band, lift + band], rel=1e-9)
    assert all(0 < r < 3 for r in tp["cost_rises"])
    expect = min(max(1 / np.sqrt(min(tp["cost_rises"])), 1.0), MAX_WIDENING)
    assert tp["widening"] == pytest.approx(expect)
    assert abs(lift - case.true_lift) <= 2 * res.lift_std[-1]


def test_auto_routes_a_record_without_a_transient_to_the_steady_estimator(setup):
    """The same tail under ``record = auto``: no ringing at its start, so the steady estimator answers,
    and its band holds the truth (the release's decay left in the tail is part of its misfit)."""
    model, case = setup
    rec = case.measurements
    k = int(np.searchsorted(rec.t, 0.5))
    meas = Measurements(rec.t[k:] - rec.t[k], rec.values[k:], rec.sensor_names, None, "steady")
    res = identify_record(model, meas, RecordSettings(membrane_model="fvk"))
    assert "tension" in res.info and "tension_profile" not in res.info
    lift, band = res.reported_lift
    assert abs(lift - case.true_lift) <= 2 * band
