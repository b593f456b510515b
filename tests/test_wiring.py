"""Wiring checks (issue 32, items 7/8): a gain set wrong, an offset forgotten, a swapped pair.

On the stand-in (``examples/data/tunnel_300Hz.csv``: FvK truth on a 49x25 mesh, prestrain off the
problem file's, 3 % buffeting) and on a transient record (FvK full order on a 37x19 mesh, released
from rest under the tunnel pressure, 1 kHz, 0.5 s, 2 % noise): each mistake is warned naming its
sensor(s); the clean records give no finding. The forgotten offset is the lab-data test's S4 bridge
zero (1000 mV at 1.25e-5 per mV: +0.0125 of stretch, about its reading)."""

from functools import cache
from pathlib import Path

import numpy as np
import pytest

from wingopt.estimation.core.record_problem import ParameterPrior
from wingopt.estimation.core.record_settings import RecordSettings
from wingopt.estimation.steady.estimator import steady_identify
from wingopt.estimation.steady.wiring import OR_THE_LOAD, check_steady, check_transient
from wingopt.measurements import Measurements, read_measurements
from wingopt.membrane import (
    MembraneModel,
    MembraneParameters,
    RecordProtocol,
    forward_model,
    leading_edge_load,
    simulate_truth,
    tunnel_load,
)
from wingopt.problem import load_problem

ROOT = Path(__file__).resolve().parents[1]
S = RecordSettings(membrane_model="fvk")


@pytest.fixture(scope="module")
def setup():
    problem = load_problem("membrane")
    meas, _ = read_measurements(ROOT / "examples" / "data" / "tunnel_300Hz.csv", problem.sensor_names)
    model = MembraneModel.from_problem(problem)
    prior = ParameterPrior.from_problem(problem, S.free, S.prestrain_rel, S.damping_rel)
    return problem, meas, model, prior


@cache
def _transient() -> tuple[np.ndarray, np.ndarray]:
    problem = load_problem("membrane")
    fwd = forward_model(problem, "fvk", nodes=(37, 19), params=MembraneParameters(0.056, 0.046, 1.0, 1.0))
    protocol = RecordProtocol(t_end=0.5, dt=1e-3, start="rest", noise_fraction=0.02, seed=3)
    rec = simulate_truth(fwd, tunnel_load("tunnel-LE", problem.width, problem.height), protocol)
    return rec.measurements.t, rec.measurements.values


def _wired_wrong(y: np.ndarray, mistake: str) -> np.ndarray:
    y = y.copy()
    if mistake == "gain 0.1x":
        y[:, 1] *= 0.1
    elif mistake == "gain 10x":
        y[:, 1] *= 10.0
    elif mistake == "swap":
        y[:, [0, 1]] = y[:, [1, 0]]
    elif mistake == "offset":
        y[:, 3] += 1000.0 * 1.25e-5
    return y


EXPECTED = {  # mistake -> (finding's kind, the sensors it names)
    "gain 0.1x": ("gain", ("S2",)),
    "gain 10x": ("gain", ("S2",)),
    "swap": ("swap", ("S1", "S2")),
    "offset": ("offset", ("S4",)),
}


def test_the_clean_stand_in_has_no_wiring_finding(setup):
    problem, meas, model, prior = setup
    res = steady_identify(model, meas)
    assert res.info["wiring"]["checked"] and res.info["wiring"]["findings"] == []
    assert not any("sensor" in w and "?" in w for w in res.info["warnings"])


@pytest.mark.parametrize(
    "mistake", [m if m != "gain 10x" else pytest.param(m, marks=pytest.mark.slow) for m in EXPECTED]
)
def test_a_wiring_mistake_on_the_stand_in_is_named(setup, mistake):
    """Measured (chi-square the correction removes): 0.1x 4342, 10x 6991, swap 3359, offset 769."""
    problem, meas, model, prior = setup
    rep = check_steady(model, meas.t, _wired_wrong(meas.values, mistake), prior, problem.identification.initial_load)
    kind, sensors = EXPECTED[mistake]
    assert len(rep.findings) == 1, rep
    f = rep.findings[0]
    assert (f.mistake, f.sensors) == (kind, sensors), f.message
    assert all(s in f.message for s in sensors) and f.evidence > 100
    if kind == "gain":
        assert f.ratio == pytest.approx(0.1 if "0.1x" in mistake else 10.0, rel=0.15)


def test_the_steady_route_says_a_gain_set_wrong(setup):
    """The route keeps its answer (the check never changes it) and says what it found."""
    problem, meas, model, prior = setup
    res = steady_identify(model, Measurements(meas.t, _wired_wrong(meas.values, "gain 0.1x"), meas.sensor_names))
    said = [w for w in res.info["warnings"] if "sensor S2's mean is" in w]
    assert len(said) == 1 and "a gain set wrong?" in said[0] and said[0].endswith(OR_THE_LOAD)
    assert res.info["wiring"]["findings"][0]["sensors"] == ("S2",)


def test_a_clean_record_under_a_load_outside_the_shapes_is_named_with_the_load_as_its_alternative(setup):
    """Four means cannot tell a wiring mistake from a load the thin-airfoil shapes cannot make: a clean
    record under the leading-edge load (FvK truth 37x19, from rest, 1 s at 300 Hz, 1 % noise) reads
    S4 at 0.58x (benchmarks/wiring_reach.py), and the finding names the load as the alternative."""
    problem, _, model, prior = setup
    fwd = forward_model(problem, "fvk", nodes=(37, 19), params=MembraneParameters(0.056, 0.046, 1.0, 1.0))
    protocol = RecordProtocol(t_end=1.0, dt=1 / 300, start="rest", noise_fraction=0.01, seed=5)
    rec = simulate_truth(fwd, leading_edge_load(problem.width, problem.height, 200.0), protocol)
    rep = check_transient(model, rec.measurements.t, rec.measurements.values, prior, 200.0)
    assert [f.sensors for f in rep.findings] == [("S4",)]
    assert 0.5 < rep.findings[0].ratio < 0.7 and rep.findings[0].message.endswith(OR_THE_LOAD)


def test_the_clean_transient_record_has_no_wiring_finding(setup):
    problem, _, model, prior = setup
    t, y = _transient()
    rep = check_transient(model, t, y, prior, problem.identification.initial_load)
    assert rep.checked and rep.findings == ()


@pytest.mark.parametrize("mistake", [m if m == "swap" else pytest.param(m, marks=pytest.mark.slow) for m in EXPECTED])
def test_a_wiring_mistake_on_a_transient_record_is_named(setup, mistake):
    """On the settled half of the record (its mean): gains and swaps as on the stand-in; an offset and a
    swap can make equally consistent means and, with no buffeting to tell them apart, both are named."""
    problem, _, model, prior = setup
    t, y = _transient()
    rep = check_transient(model, t, _wired_wrong(y, mistake), prior, problem.identification.initial_load)
    kind, sensors = EXPECTED[mistake]
    assert len(rep.findings) == 1
    f = rep.findings[0]
    if kind == "offset":
        assert "sensor S4's gain or offset" in f.message or f.sensors == ("S4",), f.message
    else:
        assert (f.mistake, f.sensors) == (kind, sensors), f.message
