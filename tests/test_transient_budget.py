"""The transient route's work budget (``RecordSettings.max_total_iter``, ``cpu_s``): every fit of a
record draws on one budget, the fits stop when it is spent, the alternatives left are named, and the
result says so; within it the answer is the unlimited one (the default budget, 160 iterations, is
above the protocol's records: L3, the worst, took 143 before its prior conflict went to the frame
prior first, 35 since)."""

import pytest

from wingopt.errors import InputError
from wingopt.estimation.records import RecordSettings, identify_record


def test_within_the_budget_the_answer_is_the_unlimited_one(fvk_short_record):
    model, meas = fvk_short_record
    free = identify_record(model, meas, RecordSettings(membrane_model="fvk", max_total_iter=10**6))
    dflt = identify_record(model, meas, RecordSettings(membrane_model="fvk"))
    b = dflt.info["budget"]
    assert not b["exhausted"] and b["iterations"] == free.info["budget"]["iterations"] < b["max_total_iter"]
    assert float(dflt.lift[-1]) == float(free.lift[-1])
    assert not any("work budget" in w for w in dflt.info["warnings"])


def test_a_spent_budget_stops_the_fits_and_says_so(fvk_short_record):
    model, meas = fvk_short_record
    res = identify_record(model, meas, RecordSettings(membrane_model="fvk", max_total_iter=3))
    b = res.info["budget"]
    assert b["exhausted"] and b["iterations"] == 3 and not res.info["converged"]
    said = "stopped at the record's work budget (3 Levenberg-Marquardt iterations"
    assert any(said in w for w in res.info["warnings"])
    cpu = identify_record(model, meas, RecordSettings(membrane_model="fvk", cpu_s=1e-6))
    assert cpu.info["budget"]["exhausted"] and cpu.info["budget"]["iterations"] <= 1


def test_budget_settings_are_checked():
    with pytest.raises(InputError, match="max_total_iter = 0"):
        RecordSettings(max_total_iter=0)
    with pytest.raises(InputError, match="cpu_s = -1"):
        RecordSettings(cpu_s=-1)
