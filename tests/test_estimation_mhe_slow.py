"""The issue's "Must show" list on the full protocol (slow: run with ``pytest -m slow``).

Truth on 49x25, estimator on 25x13, 1 s at 1 ms, noise level estimated from the data. The same
numbers, with the JEKF columns, are produced by ``wingopt compare membrane --n-sign-seeds 20
--consistency`` into ``docs/estimation_comparison.md``.
"""

import numpy as np
import pytest

from wingopt.workflows.comparison import comparison_study, consistency_study, sign_and_band_study
from wingopt.workflows.studies import summarize

pytestmark = pytest.mark.slow

LIMITS = {("L1", 0.01): 0.02, ("L1", 0.05): 0.03, ("L2", 0.01): 0.04, ("L2", 0.05): 0.06}


@pytest.fixture(scope="module")
def table(membrane_problem):
    recs = comparison_study(membrane_problem, methods=("mhe",), jobs=2)
    return recs, {(r["load"], r["noise"]): r for r in summarize(recs)}


def test_mhe_mean_final_load_errors(table):
    _, rows = table
    for key, limit in LIMITS.items():
        assert rows[key]["load_error"]["mean"] <= limit, (key, rows[key]["load_error"])
    assert rows[("L3", 0.01)]["load_error"]["mean"] <= 0.35  # fixed-edge load space; measured 0.345
    assert rows[("L3", 0.05)]["load_error"]["mean"] <= 0.355  # measured 0.3503, see the xfail below


@pytest.mark.xfail(strict=True, reason="not met: L3 at 5 % measured 0.3503 (fixed-edge prior bias; oracle 0.346)")
def test_l3_5_percent_within_0_35(table):
    _, rows = table
    assert rows[("L3", 0.05)]["load_error"]["mean"] <= 0.35


def test_mhe_lift_within_5_percent_of_the_absolute_load_at_1_percent_noise(table):
    recs, _ = table
    assert max(r.lift_error for r in recs if r.noise == 0.01 and r.load in ("L1", "L2")) <= 0.05  # measured 0.006
    assert max(r.lift_error for r in recs if r.noise == 0.01 and r.load == "L3") <= 0.13  # measured 0.120


@pytest.mark.xfail(strict=True, reason="not met: the fixed-edge space puts the L3 lift 12 % low (free edges: 3 %)")
def test_l3_lift_within_5_percent(table):
    recs, _ = table
    assert max(r.lift_error for r in recs if r.noise == 0.01 and r.load == "L3") <= 0.05


def test_data_only_lambda_within_1_5_of_the_oracle(table):
    recs, _ = table
    ratios = [r.load_error / r.oracle_load_error for r in recs]
    assert max(ratios) <= 1.5, ratios


def test_sign_and_lift_band_over_20_seeds(membrane_problem):
    recs = sign_and_band_study(membrane_problem, seeds=range(20), jobs=2)
    for load in ("L1", "L2", "L3"):
        assert sum(r.sign_ok for r in recs if r.load == load) == 20
    covered = sum(r.covered for r in recs if r.load == "L1")
    assert 12 <= covered <= 15, covered


def test_consistency_error_falls_with_sensor_count(membrane_problem):
    rows = consistency_study(membrane_problem)
    errs = [r["load_error_mean"] for r in rows]
    assert [r["sensors"] for r in rows] == [4, 12, 32]
    assert np.all(np.diff(errs) < 0), errs


def test_free_edge_option_with_evidence_state_prior_on_l3(membrane_problem):
    """The free-edge aim (L3 <= 0.2) with ``--load-space free --state-prior evidence``, seeds 0–4, 1 %."""
    from wingopt.estimation.mhe import STATE_PRIOR_EVIDENCE, MHESettings

    settings = MHESettings(load_space="free", state_prior_choices=STATE_PRIOR_EVIDENCE)
    recs = comparison_study(
        membrane_problem, ("L3",), (0.01,), methods=("mhe",), mhe_settings=settings, oracle=False, jobs=2
    )
    assert np.mean([r.load_error for r in recs]) <= 0.2  # measured 0.162
    assert max(r.lift_error for r in recs) <= 0.05  # measured 0.024
    assert all(r.sign_ok for r in recs)


@pytest.mark.xfail(
    strict=True, reason="not met out of sample: worst ratio 1.58 (L1 5 % seed 201), 1.54 (L2 5 % seed 203)"
)
def test_lambda_rule_within_1_5_of_the_oracle_out_of_sample(membrane_problem):
    """The knee rule on fresh noise seeds 200–204 (its constants were set on seeds overlapping 0–4)."""
    recs = comparison_study(membrane_problem, seeds=range(200, 205), methods=("mhe",), jobs=2)
    for key, limit in LIMITS.items():
        assert np.mean([r.load_error for r in recs if (r.load, r.noise) == key]) <= limit  # met (0.014–0.033)
    assert max(r.load_error / r.oracle_load_error for r in recs) <= 1.5
