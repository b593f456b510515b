"""Model-form error in the full-field band (issue 32, item 4): loads outside the prior's families.

Truth: FvK on 37x19 (finer than the estimator's 25x13), prestrain (0.06, 0.04) where the problem
file says 0.05; a calibration's prior as in ``tests/test_fullfield.py`` (its offsets +2.4 % and
-0.9 %, never the true prestrain, never the load); 150 DIC frames of the static equilibrium. A
sharp leading-edge rise (within 5 mm) is outside every prior's family: the mean field misfits at
chi-square ~7 per datum, and the band takes in the lifts of the richer spaces, the other priors and
the held-out fits the evidence does not exclude, without moving the lift. A load inside the families
(``tunnel-LE``) fits to its noise and keeps its band. The five-load table at 49x25:
``benchmarks/dic_outside_families.py`` (docs/dic.md).
"""

from __future__ import annotations

import numpy as np
import pytest
from _dic import calibrated

from wingopt.estimation.fullfield import FullFieldSettings, fullfield_identify
from wingopt.estimation.fullfield.estimator import ADEQUATE_CHI2
from wingopt.estimation.fullfield.model_form import ADMITS
from wingopt.fe import integrate
from wingopt.membrane import MembraneModel, MembraneParameters, PressureLoad, tunnel_load
from wingopt.membrane.dic_synth import synthesize_frames
from wingopt.membrane.full import FvKMembrane
from wingopt.workflows.studies import load_field

E0 = (0.06, 0.04)


def sharp_le(W: float, H: float) -> PressureLoad:
    """A leading-edge rise within 5 mm, then falling to 40 % at the trailing edge, uniform in span."""
    rise = lambda x, y: 180.0 * np.clip(x / 0.005, 0, 1) * (1 - 0.6 * x / W) + 0 * y  # noqa: E731
    return PressureLoad("sharp-le", rise, "a leading-edge rise within 5 mm", breaks_x=(0.005,))


def seen_error(load, result, model, frames, n: int = 200) -> float:
    """Relative L2 field error where the frames see: a midpoint grid over the box their points span
    (the grid's cell centres: 1.75 mm inside the frame, most of the 5 mm rise is outside it)."""
    xs = np.linspace(frames.x.min(), frames.x.max(), n + 1)
    ys = np.linspace(frames.y.min(), frames.y.max(), n // 2 + 1)
    X, Y = np.meshgrid(0.5 * (xs[1:] + xs[:-1]), 0.5 * (ys[1:] + ys[:-1]))
    true, est = load(X, Y), load_field(result, model)(X, Y)
    return float(np.sqrt(np.sum((true - est) ** 2) / np.sum(true**2)))


@pytest.fixture(scope="module")
def runs(membrane_problem):
    p = membrane_problem
    truth = FvKMembrane(p, (37, 19), MembraneParameters(*E0))
    model = MembraneModel.from_problem(calibrated(p, E0))
    out = {}
    for load in (sharp_le(p.width, p.height), tunnel_load("tunnel-LE", p.width, p.height)):
        sol = truth.static(truth.linear.gram @ truth.linear.project(load))
        frames = synthesize_frames(truth, np.arange(150) / 300, np.repeat(sol.z[None], 150, 0), seed=5)
        res = fullfield_identify(model, frames, FullFieldSettings(mode="steady"))
        out[load.name] = (res, integrate(truth.space, load, order=8), seen_error(load, res, model, frames))
    return out


def test_a_load_outside_the_families_widens_the_band_by_the_spaces_spread(runs):
    res, true_lift, field = runs["sharp-le"]
    info = res.info
    mf = info["model_form"]
    assert info["adequacy"]["chi2_per_datum"] > ADEQUATE_CHI2 and not info["model_adequate"]
    assert mf is not None and mf["chi2_per_datum"] == info["adequacy"]["chi2_per_datum"]
    # the lift does not move: it is the priors' mixture, as without the model-form term
    mix = sum(s["weight"] * s["lift_N"] for s in info["solutions"])
    assert res.lift[-1] == pytest.approx(mix, rel=1e-12) and mf["lift_N"] == pytest.approx(mix, rel=1e-12)
    # the band: the fit's and the spread in quadrature; the spread is the farthest admitted lift
    admitted = [a for a in mf["alternatives"] if a["admitted"]]
    assert {a["admitted"] for a in mf["alternatives"]} == {True, False}  # the thin-airfoil shapes are excluded
    assert all(a["chi2_per_datum"] <= ADMITS * mf["chi2_per_datum"] for a in admitted)
    assert mf["spread_N"] == pytest.approx(max(abs(a["lift_N"] - mix) for a in admitted), rel=1e-12)
    assert mf["spread_N"] > 1e-3 * abs(mix)
    assert res.lift_std[-1] == pytest.approx(np.hypot(mf["band_before_N"], mf["spread_N"]), rel=1e-12)
    assert res.lift_std[-1] > mf["band_before_N"]
    # a richer space fits the field better than the chosen one
    richer = [a for a in mf["alternatives"] if "shapes" in a["label"]]
    assert min(a["chi2_per_datum"] for a in richer) < 0.7 * mf["chi2_per_datum"]
    assert any("outside the prior's families" in w for w in info["warnings"])
    # what issue 32 asks: lift within 2 % or the truth inside 2 bands; the field within 10 % where the frames see
    assert abs(res.lift[-1] / true_lift - 1) < 0.02 or abs(res.lift[-1] - true_lift) < 2 * res.lift_std[-1]
    assert field < 0.10


def test_a_load_inside_the_families_keeps_its_band(runs):
    res, true_lift, field = runs["tunnel-LE"]
    info = res.info
    assert info["model_adequate"] and info["model_form"] is None
    assert res.lift_std[-1] == pytest.approx(info["steady_lift_std_N"], rel=1e-12)
    assert not any("outside the prior's families" in w for w in info["warnings"])
    assert abs(res.lift[-1] / true_lift - 1) < 0.01 and field < 0.10
