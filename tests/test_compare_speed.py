"""Speed without changing the numbers (issue 26): the error histories of the identify plots, the
cached basis matrices and truths; compare's JEKF order and its MHE–JEKF overlay plots."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from wingopt.errors import InputError
from wingopt.problem import load_problem
from wingopt.results import OwnedDirectory


@pytest.fixture(scope="module")
def run():
    from wingopt.workflows.identify import identify

    return identify(load_problem("membrane"), load="L1", noise_percent=1, t_end=0.2, method="mhe")


def test_error_histories_match_the_per_sample_metrics(run):
    """The one-evaluation-per-mesh history equals the truth record's own metrics sample by sample."""
    from wingopt.plots.identify import error_histories

    result, case = run.result, run.case
    idx = np.array([0, 50, 120, result.t.size - 1])
    t0 = time.process_time()
    le, de = error_histories(case, result, run.model, idx)
    fast = time.process_time() - t0
    for j, k in enumerate(idx):
        kt = int(np.argmin(np.abs(case.trajectory.t - result.t[k])))
        assert le[j] == pytest.approx(case.load_error(run.load_field(k)), rel=1e-10)
        assert de[j] == pytest.approx(case.deflection_error(run.model.field(result.deflection[k]), kt), rel=1e-10)
    assert le[-1] < 0.1 and fast < 5.0


def test_basis_matrices_of_large_point_sets_are_built_once():
    from wingopt.membrane import MembraneModel

    space = MembraneModel.from_problem(load_problem("membrane")).space
    x, y, _ = space.cells().quadrature(8)
    first = space.basis_matrix(x, y)
    again = space.basis_matrix(x.copy(), y.copy())  # the same points, another array
    assert again is first
    moved = space.basis_matrix(x * 0.999, y)
    assert moved is not first and abs(moved - first).max() > 0
    small = space.basis_matrix(x.ravel()[:10], y.ravel()[:10])
    assert small is not space.basis_matrix(x.ravel()[:10], y.ravel()[:10])  # small sets: not cached
    assert len(space._basis_cache) <= 4


def test_the_last_truth_is_reused_only_for_the_same_seeded_case():
    from wingopt.workflows.protocols import simulate_case

    prob = load_problem("membrane")
    a = simulate_case(prob, "L1", 0.01, 3, (25, 13), 0.05)
    b = simulate_case(prob, "L1", 0.01, 3, (25, 13), 0.05)
    c = simulate_case(prob, "L1", 0.01, 4, (25, 13), 0.05)
    assert b.trajectory is a.trajectory and np.array_equal(a.measurements.values, b.measurements.values)
    assert c.trajectory is not a.trajectory and not np.array_equal(a.measurements.values, c.measurements.values)
    u = simulate_case(prob, "L1", 0.01, None, (25, 13), 0.05)
    v = simulate_case(prob, "L1", 0.01, None, (25, 13), 0.05)
    assert not np.array_equal(u.measurements.values, v.measurements.values)  # seed None: fresh noise


def test_compare_jekf_order_keys_and_costs():
    from wingopt.cli.compare import parse_order
    from wingopt.workflows.comparison import JEKF_MODES, ComparisonPreset
    from wingopt.workflows.sweep.protocol import protocol_tasks

    assert parse_order("full") is None and parse_order("60") == 60
    for bad in ("0", "-3", "many"):
        with pytest.raises(InputError, match="jekf-order"):
            parse_order(bad)
    assert ComparisonPreset().jekf_modes == JEKF_MODES == 60
    with pytest.raises(InputError, match="jekf-order"):
        ComparisonPreset(jekf_modes=0)
    prob = load_problem("membrane")
    runs = [("L1", 0.01, 0, m) for m in ("mhe", "jekf-seed", "jekf-tuned")]
    reduced, _ = protocol_tasks(prob, runs, truth_nodes=(49, 25), oracle=True, jekf_modes=60)
    full, _ = protocol_tasks(prob, runs, truth_nodes=(49, 25), oracle=True)
    keys = {json.loads(t.key)["method"]: json.loads(t.key) for t in reduced}
    assert "jekf_modes" not in keys["mhe"] and keys["jekf-tuned"]["jekf_modes"] == 60
    assert all("jekf_modes" not in json.loads(t.key) for t in full)  # the exact filter: the pre-option keys
    cost = {json.loads(t.key)["method"]: t.cost for t in reduced}
    full_cost = {json.loads(t.key)["method"]: t.cost for t in full}
    assert cost["mhe"] == full_cost["mhe"]
    assert cost["jekf-tuned"] < full_cost["jekf-tuned"] / 10
    # cheapest first: the exact JEKFs (a minute each) after the MHE (with its oracle grid), the reduced ones before
    assert full_cost["mhe"] < full_cost["jekf-tuned"] < full_cost["jekf-seed"]
    assert cost["jekf-tuned"] < cost["mhe"]


def _history(lift, std):
    t = np.linspace(0, 1, 11)
    return {"t": list(t), "lift_N": list(lift + 0 * t), "lift_std_N": None if std is None else [std] * 11}


def test_compare_writes_an_mhe_jekf_overlay_per_load(tmp_path):
    from wingopt.workflows.comparison import write_overlays

    recs = [
        {"load": "L1", "noise": 0.01, "seed": 0, "method": "mhe", "true_lift": 0.79, "history": _history(0.78, 0.01)},
        {"load": "L1", "noise": 0.01, "seed": 0, "method": "jekf-tuned", "true_lift": 0.79,
         "params": {"jekf_modes": 60}, "history": _history(0.77, 0.02)},
        {"load": "L1", "noise": 0.05, "seed": 0, "method": "mhe", "true_lift": 0.79, "history": _history(0.7, 0.1)},
        {"load": "L2", "noise": 0.01, "seed": 0, "method": "mhe", "true_lift": 0.0, "history": _history(0.0, None)},
        {"load": "L3", "noise": 0.01, "seed": 0, "method": "mhe", "true_lift": 0.5},  # an old record: no history
        {"load": "L3", "noise": 0.01, "seed": 0, "method": "jekf-seed", "true_lift": 0.5},
    ]  # fmt: skip
    owner = OwnedDirectory(tmp_path / "cmp")
    assert write_overlays(owner, recs) == ["overlay-L1.png"]  # L2: no JEKF; L3: no histories
    png = tmp_path / "cmp" / "overlay-L1.png"
    assert png.read_bytes()[:4] == b"\x89PNG" and png.stat().st_size > 10_000
    assert owner.owns("overlay-L1.png")


def test_protocol_record_keeps_a_short_lift_history(run):
    from wingopt.workflows.sweep.protocol import lift_history

    h = lift_history(run.result, points=21)
    assert len(h["t"]) == len(h["lift_N"]) == len(h["lift_std_N"]) == 21
    assert h["t"][0] == pytest.approx(run.result.t[0]) and h["t"][-1] == pytest.approx(run.result.t[-1])
    assert h["lift_N"][-1] == pytest.approx(float(run.result.lift[-1]), rel=1e-5)
    json.dumps(h)
