"""The shipped examples run and give the numbers their docstrings promise.

Each example is imported from its file (``examples/`` is not a package) and its ``main`` called.
"""

import importlib.util
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _example(name: str):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_identify_from_csv_example(capsys):
    """``examples/identify_from_csv.py`` on the shipped SYNTHETIC 300 Hz record (constant load after
    a 40 ms ramp from rest, true lift 0.4211 N in the file's header).

    Measured: lift 0.4197 +- 0.0039 N (-0.3 %), onset 50 ms skipped, no restart. Tolerance 2 % of
    the truth: the lift band is +-0.9 % (1 sigma) and the estimator's bias on smooth single-bump loads
    is -0.1 to -1.4 % (design records: docs/estimation.md), so 2 % fails only on a real regression
    (before the consistency test: -37 %), far inside the seed's 5 % tunnel agreement.
    """
    ex = _example("identify_from_csv")
    out = ex.main()
    printed = capsys.readouterr().out
    assert out["true_lift_N"] == pytest.approx(0.421124, abs=1e-6)  # read from the header, printout only
    assert out["lift_N"] == pytest.approx(out["true_lift_N"], rel=0.02)
    assert 0.001 < out["lift_std_N"] < 0.01
    assert abs(out["lift_N"] - out["true_lift_N"]) < 2 * out["lift_std_N"]
    assert out["samples"] == 451 and out["missing_rows"] == 6 and out["window_samples"] == 60
    assert 0.04 - 1e-9 <= out["onset_skipped_s"] <= 0.1  # the 40 ms ramp is left out
    assert out["restarts"] == 0
    assert out["lift_spread_last_half_N"] < 0.01 * out["true_lift_N"]  # constant load: a flat history
    assert "final lift" in printed and "SYNTHETIC" in printed and "lift history" in printed
