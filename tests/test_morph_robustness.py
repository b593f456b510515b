"""Issue 34, step 4: the morph-robustness sweep (``kind = "morph"`` specs of ``wingopt sweep``)."""

import numpy as np
import pytest

from wingopt.errors import InputError
from wingopt.workflows.morph_robustness import ISSUE_PLANTS, excess_table, sample_plants
from wingopt.workflows.morph_sweep import MorphSweepSpec, morph_tasks
from wingopt.workflows.sweep.engine import Engine, EngineSettings
from wingopt.workflows.sweep.run import run_sweep
from wingopt.workflows.sweep.spec import parse_spec

SPEC = {
    "kind": "morph",
    "problem": "plate",
    "mesh": "7x31",
    "t_end": 0.3,
    "shapes": ["camber"],
    "controllers": ["qp", "qp-today"],
    "plants": {"count": 2, "seed": 3, "sensor_bias": [0.0, 0.02]},
    "cases": [{"name": "stiff weak", "scales": {"moduli": 1.1, "d33": 0.8}}],
}


def test_sample_plants_are_in_their_ranges_and_reproducible():
    a, b = sample_plants(50, seed=4), sample_plants(50, seed=4)
    assert a == b and len({p.name for p in a}) == 50
    s = np.array([[p.scales["moduli"], p.scales["d33"], p.scales["damping"]] for p in a])
    assert s[:, 0].min() >= 0.9 and s[:, 0].max() <= 1.1
    assert s[:, 1].min() >= 0.8 and s[:, 1].max() <= 1.2
    assert s[:, 2].min() >= 0.5 and s[:, 2].max() <= 2.0
    assert (s[:, 2] < 1).mean() == pytest.approx(0.5, abs=0.2)  # log-uniform: half below 1
    assert all(p.hysteresis == 0.15 and p.creep == 0.0 for p in a)
    with pytest.raises(InputError, match="plants.stiffness"):
        sample_plants(2, ranges={"stiffness": [1, 2]})


def test_morph_spec_parses_and_refuses():
    spec = parse_spec(dict(SPEC), "s.toml")
    assert isinstance(spec, MorphSweepSpec) and spec.problem.nodes == (7, 31)
    assert [r.case.name for r in spec.runs] == ["stiff weak", "random 0", "random 1"]
    tasks, shared = morph_tasks(spec)
    assert len(tasks) == 3 and len({t.key for t in tasks}) == 3 and len(shared) == 1
    with_issue = parse_spec({**SPEC, "issue_plants": True}, "s.toml")
    assert [r.case for r in with_issue.runs[:3]] == list(ISSUE_PLANTS)
    for change, needle in [
        ({"controllers": ["pid"]}, "controllers = \\['pid'\\]: expected a non-empty list of qp, qp-today, lqr-sat"),
        ({"shapes": []}, "shapes = \\[\\]"),
        ({"cases": [{"name": "x", "scales": {"d33": 0}}]}, "scales: plant-scale d33 = 0"),
        ({"cases": [{"name": "x", "hysteresis": 0.9}]}, "hysteresis = 0.9: expected a number in \\[0, 0.3\\]"),
        ({"plants": {"count": 0}}, "plants.count = 0"),
        ({"problem": "membrane"}, "expected a plate problem"),
        ({"bogus": 1}, "bogus = 1: expected one of the morph spec keys"),
    ]:
        with pytest.raises(InputError, match=needle):
            parse_spec({**SPEC, **change}, "s.toml")


def test_sweep_runs_resumes_and_tabulates(tmp_path):
    spec = parse_spec({**SPEC, "plants": {"count": 1, "seed": 3}}, "s.toml")
    with Engine(EngineSettings(mode="serial", progress=False)) as eng:
        first = run_sweep(spec, tmp_path / "out", eng)
        again = run_sweep(spec, tmp_path / "out", eng, resume=True)
    assert first["ran"] == 2 and first["recorded"] == 2 and not first["failed"]
    assert again["ran"] == 0 and again["recorded"] == 2
    rows = {(r["controller"], r["metric"]): r for r in first["cases"]}
    assert set(rows) == {(c, m) for c in ("qp", "qp-today") for m in ("relative_excess", "settled_relative_excess")}
    assert all(r["plants"] == 2 and r["within_limits"] == 1.0 for r in rows.values())
    assert (tmp_path / "out" / "table.csv").read_text().startswith("shape,controller,metric,plants,median")


def test_excess_table_statistics():
    recs = [
        {"results": {"twist": {"qp": {"relative_excess": v, "within_limits": True}}}} for v in (0.0, 0.01, 0.03, 0.1)
    ]
    (row,) = excess_table(recs)
    assert row["median"] == pytest.approx(0.02) and row["max"] == 0.1 and row["within_0.02"] == 0.5
