"""Steady tunnel records (issue 23): the loaded wing in steady flow, four sensors to the lift.

Truth: the full-order FvK equilibrium on a finer mesh (37x19) under a tunnel pressure that acts up
to the frame, prestrains off the problem file's 0.05 by ±20 %; the estimator is the modal FvK model
on 25x13 (defect-corrected to its full order), its load priors the frame prior (interior and
free-edge shapes) and the aerodynamic shapes, neither of which holds the truth's pressure exactly.
"""

from __future__ import annotations

import numpy as np
import pytest
from _tunnel import static_truth, steady_record

from wingopt.estimation.steady.estimator import is_steady, steady_identify
from wingopt.membrane import MembraneModel
from wingopt.problem import load_problem


@pytest.fixture(scope="module")
def problem():
    return load_problem("membrane")


def _identify(problem, load, truth, **prior):
    meas = steady_record(load, truth)
    res = steady_identify(MembraneModel.from_problem(problem.with_identification(**prior)), meas)
    _, true_lift = static_truth(load, truth)
    return res, true_lift


@pytest.mark.parametrize(
    "load, truth", [("tunnel-LE", (0.04, 0.04)), ("tunnel-LE", (0.06, 0.06)), ("uniform", (0.05, 0.05))]
)
def test_four_means_alone_give_a_band_that_holds_the_truth(problem, load, truth):
    """No calibration, no declared load: the truth inside 2 bands, and the warnings say why the band
    is wide (the tension is unidentified; the lobes' signs are not told apart). A uniform pressure is
    none of the priors' shapes; under the interior prior it read 42 % low at 15 bands, "adequate"."""
    res, true_lift = _identify(problem, load, truth)
    lift, band = float(res.lift.mean()), float(res.lift_std.mean())
    assert abs(lift - true_lift) <= 2.0 * band
    assert any("does not identify the tension" in w for w in res.info["warnings"])


DECLARED = {"leading_edge": "x0", "pressure_prior": "aerodynamic"}


@pytest.mark.parametrize(
    "prestrain, calibrated, declared",
    [
        ((0.05, 0.05), (0.0505, 0.0496), DECLARED),
        ((0.06, 0.04), (0.0597, 0.0406), DECLARED),
        ((0.06, 0.06), (0.0603, 0.0596), DECLARED),
        ((0.06, 0.04), (0.0597, 0.0406), {}),
        ((0.04, 0.04), (0.0404, 0.0397), {}),
    ],
)
def test_a_calibrated_tension_gives_the_lift(problem, prestrain, calibrated, declared):
    """With the tension of a calibration (a posterior of 1-2 % as `wingopt calibrate` measures on a
    release record, its mean off the truth by about 1 %) the lift is within 3 % and no tension warning
    is given: with an aerodynamic load declared, and with nothing declared (the default prior weighs
    the frame prior and the aerodynamic shapes at either edge; under the frame prior alone this
    record read 53 % low, its lobe signs open)."""
    res, true_lift = _identify(
        problem,
        "tunnel-LE",
        prestrain,
        prestrain=calibrated,
        prestrain_std=(0.001, 0.001),
        prestrain_correlation=-0.9,
        **declared,
    )
    lift = float(res.lift.mean())
    assert abs(lift - true_lift) <= 0.03 * true_lift
    assert abs(lift - true_lift) <= 2.0 * float(res.lift_std.mean())
    assert not any("tension" in w for w in res.info["warnings"])
    assert res.info["chosen"] == "aerodynamic x0"


def test_a_load_of_another_shape_is_left_to_the_frame_prior(problem):
    """An off-centre bump is no thin-airfoil load: the aerodynamic shapes do not make its mean and the
    default prior's answer is the frame prior's, the truth inside its band."""
    res, true_lift = _identify(problem, "tunnel-bump", (0.05, 0.05))
    weights = {s["prior"].split(",")[0]: 0.0 for s in res.info["solutions"]}
    for s in res.info["solutions"]:
        weights[s["prior"].split(",")[0]] += s["weight"]
    assert weights.get("frame", 0.0) > 0.99, res.info["solutions"]
    assert abs(float(res.lift.mean()) - true_lift) <= 2.0 * float(res.lift_std.mean())


def test_an_antisymmetric_load_undeclared_shape_has_zero_lift_in_its_band(problem):
    """(LE(x) - LE(W - x)) / 2: zero net lift, two lobes the quadratic sensors cannot sign."""
    res, true_lift = _identify(problem, "tunnel-anti", (0.05, 0.05))
    assert true_lift == pytest.approx(0.0, abs=1e-12)
    assert abs(float(res.lift.mean())) <= 2.0 * float(res.lift_std.mean())


def test_a_trailing_edge_load_is_within_5_percent_or_2_bands_with_a_warning(problem):
    res, true_lift = _identify(problem, "tunnel-TE", (0.05, 0.05))
    err, band = abs(float(res.lift.mean()) - true_lift), float(res.lift_std.mean())
    assert err <= 0.05 * true_lift or (err <= 2.0 * band and res.info["warnings"])


def test_a_steady_record_is_told_from_a_release(problem):
    assert is_steady(steady_record("tunnel-LE", (0.05, 0.05)).values)
    t = np.arange(300) / 300.0
    ringing = 0.01 * (1 + 2 * np.exp(-t / 0.05))[:, None] * np.ones((1, 4))  # a release: 3x the level at first
    assert not is_steady(ringing)
    # The protocol's release about its static state: the mean within 7-9 %, but it rings.
    rng = np.random.default_rng(0)
    static = 0.01 * (1 + 0.3 * np.exp(-t / 0.08) * np.cos(2 * np.pi * 160 * t))[:, None] * np.ones((1, 4))
    assert not is_steady(static + 1e-5 * rng.standard_normal(static.shape))


def test_a_prior_that_misfits_the_mean_widens_its_band_and_says_so(problem):
    """A uniform pressure with the aerodynamic shapes declared and the tension calibrated: the three
    thin-airfoil amplitudes cannot make the four means (chi-square 2.7 per sensor, adequate below 4);
    the band is widened by sqrt(2.7) (the Birge ratio), and the result says so: +7.3 % at 1.3 bands,
    where the fit's own band put it at 2.1."""
    from wingopt.estimation.steady.solutions import misfit_scale

    assert misfit_scale(0.3) == 1.0 and misfit_scale(4.0) == 2.0 and misfit_scale(float("nan")) == 1.0
    res, true_lift = _identify(
        problem, "uniform", (0.05, 0.05), pressure_prior="aerodynamic", leading_edge="x0", prestrain_std=(0.001, 0.001)
    )
    lift, band = res.reported_lift
    chi2 = res.info["adequacy"]["chi2_per_datum"]
    assert 1.5 < chi2 <= 4.0 and res.info["model_adequate"]
    assert res.info["adequacy"]["band_widening"] == pytest.approx(np.sqrt(chi2))
    assert res.info["solutions"][0]["band_widening"] == pytest.approx(np.sqrt(chi2))
    assert abs(lift - true_lift) <= 2.0 * band
    assert abs(lift - true_lift) > 2.0 * band / misfit_scale(chi2)  # the fit's own band would not hold it
