"""The typed diagnostics every result carries: read from ``info`` once, written back to the same
``summary.json`` keys (issue 31: typed diagnostics that serialise to today's keys)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import wingopt as wo
from wingopt.estimation.core.diagnostics import Diagnostics
from wingopt.estimation.core.result import IdentificationResult
from wingopt.measurements import read_measurements
from wingopt.status import RunStatus

ROOT = Path(__file__).resolve().parents[1]


def _result(info: dict, lift=(0.5, 0.6)) -> IdentificationResult:
    n = len(lift)
    return IdentificationResult(
        "test", np.arange(n) * 0.1, np.zeros((n, 2)), np.zeros((n, 3)), np.array(lift), np.full(n, 0.05), info=info
    )


def test_an_info_dict_reads_into_typed_fields():
    info = {
        "warnings": ["a", "b"],
        "model": "realistic (FvK)",
        "model_adequate": False,
        "adequacy": {"chi2_per_datum": 2.5, "segments": 3},
        "converged": True,
        "statuses": ["optimal", "optimal_inaccurate"],
        "steady_lift_N": 1.75,
        "steady_lift_std_N": 0.02,
        "record": "steady",
        "parameters": {"prestrain_x": 0.05},
        "parameters_std": {"prestrain_x": 0.002},
        "dropped": ["S3"],
        "iterations": 12,  # the estimator's own detail stays in info
    }
    d = Diagnostics.of(info)
    assert d.warnings == ("a", "b") and d.model == "realistic (FvK)" and d.model_adequate is False
    assert d.chi2_per_datum == 2.5 and d.converged is True and d.record == "steady"
    assert d.solver_statuses == ("optimal", "optimal_inaccurate")
    assert d.steady_lift == (1.75, 0.02) and d.parameters == {"prestrain_x": 0.05} and d.dropped == ("S3",)
    assert d.summary() == {
        "model": "realistic (FvK)",
        "model_adequate": False,
        "dropped": ["S3"],
        "chi2_per_datum": 2.5,
        "parameters": {"prestrain_x": 0.05},
        "parameters_std": {"prestrain_x": 0.002},
    }
    res = _result(info)
    assert res.diagnostics == d and res.reported_lift == (1.75, 0.02)  # the steady lift, not the history's last
    assert res.status is RunStatus.NOT_CONVERGED  # an inaccurate solve is worse than a misfit
    assert _result({**info, "statuses": ["optimal"]}).status is RunStatus.MISFIT


def test_an_empty_info_is_the_linear_estimators_summary():
    d = Diagnostics.of({})
    assert d == Diagnostics()
    assert d.summary() == {"model": "linear", "model_adequate": None, "dropped": []}
    res = _result({})
    assert res.reported_lift == (0.6, 0.05) and res.status is RunStatus.CONVERGED


@pytest.mark.parametrize("data", ["tunnel_300Hz.csv"])
def test_a_real_runs_summary_holds_its_diagnostics(data, tmp_path):
    """The shipped stand-in record through the steady route: summary.json's top level is what its
    typed diagnostics say, and they agree with the result's own numbers."""
    problem = wo.load_problem("membrane")
    meas, _ = read_measurements(ROOT / "examples" / "data" / data, problem.sensor_names)
    run = wo.identify(problem, data=meas)
    d = run.result.diagnostics
    assert d.record == "steady" and d.steady_lift == run.result.reported_lift
    assert d.chi2_per_datum == pytest.approx(run.result.info["adequacy"]["chi2_per_datum"], rel=0)
    assert set(d.parameters) >= {"prestrain_x", "prestrain_y"} and all(v > 0 for v in d.parameters_std.values())
    out = wo.write_identify_outputs(run, tmp_path / "out", plots=False)
    summary = json.loads((out / "summary.json").read_text())
    for key, value in d.summary().items():
        assert summary[key] == json.loads(json.dumps(value)), key
    assert summary["status"] == str(run.result.status)
