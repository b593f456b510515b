"""``wingopt design-sensors``: outputs, the --write-problem round trip and bad input (small and fast)."""

from __future__ import annotations

import json
import tomllib

import numpy as np
import pytest

from wingopt.cli import main
from wingopt.problem import PROBLEMS_DIR, load_problem

CANDS = "only-rects;rect=0.02:0.05:0.01:0.025;rect=0.08:0.11:0.045:0.06;rect=0.1:0.13:0.01:0.025"


@pytest.mark.parametrize("criterion", ["a", "risk"])
def test_design_cli_round_trip(tmp_path, criterion):
    out = tmp_path / "d"
    new = tmp_path / "new.toml"
    args = ["design-sensors", "membrane", "--count", "2", "--candidates", CANDS, "--criterion", criterion]
    args += ["--t-end", "0.05", "--nominal", "1", "--out", str(out), "--write-problem", str(new), "-q"]
    assert main(args) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["count"] == 2 and summary["candidates"] == 7  # 3 rects + the problem's 4 sensors
    assert isinstance(summary["warnings"], list)
    assert summary["status"] == ("converged" if summary["relaxation"]["status"] == "optimal" else "not_converged")
    rel = summary["relaxation"]
    assert rel["bound"] <= rel["chosen_reduced"] + 1e-6 and rel["gap"] >= -1e-6
    assert (out / "layout.png").stat().st_size > 1000
    pasted = tomllib.loads((out / "sensors.toml").read_text())
    rects = [s["rect"] for s in summary["layout"]]
    assert np.allclose([s["rect"] for s in pasted["sensors"]], rects, atol=1e-6)
    # the written problem equals the original but for the sensors
    original = load_problem("membrane")
    written = load_problem(new)
    assert np.allclose([list(s.rect) for s in written.sensors], rects, atol=1e-6)
    assert written.with_sensors(original.sensors).material == original.material
    assert (written.width, written.height, written.nodes) == (original.width, original.height, original.nodes)
    assert written.identification == original.identification
    a = tomllib.loads(new.read_text())
    b = tomllib.loads((PROBLEMS_DIR / "membrane.toml").read_text())
    a.pop("sensors"), b.pop("sensors")
    assert a == b


def test_design_cli_bad_input(tmp_path, capsys):
    out = str(tmp_path / "x")
    assert main(["design-sensors", "membrane", "--count", "0", "--out", out]) == 2
    assert "count" in capsys.readouterr().err
    assert main(["design-sensors", "membrane", "--count", "2", "--candidates", "step=x", "--out", out]) == 2
    assert "step" in capsys.readouterr().err
    assert main(["design-sensors", "membrane", "--count", "2", "--noise", "0", "--out", out]) == 2
    assert "noise" in capsys.readouterr().err


def test_design_cli_montecarlo(tmp_path, capsys):
    out = tmp_path / "mc"
    args = ["design-sensors", "membrane", "--count", "2", "--candidates", CANDS, "--t-end", "0.1", "--nominal", "1"]
    assert main(args + ["--montecarlo", "2", "--out", str(out), "--no-plots", "-q"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    mc = summary["baselines"]["montecarlo"]
    assert len(mc["layouts"]) == 2 and mc["identifications"] == 2 * 4 * 2  # layouts x loads x seeds
    assert summary["predictions"]["montecarlo_relative_load_error"] == min(mc["montecarlo"])
    assert 0 < min(mc["montecarlo"]) < 2
    assert main(args + ["--criterion", "a", "--montecarlo", "2", "--out", str(tmp_path / "x")]) == 2
    assert "montecarlo" in capsys.readouterr().err


def test_write_problem_onto_an_existing_file_is_refused_without_force_and_kept_as_bak_with_it(tmp_path):
    # --write-problem goes through results.write_text_atomic: an existing file is refused unless
    # force, and then kept as NAME.bak (NAME.bak.1, ... when taken: a backup never replaces a file).
    from wingopt.errors import OutputError
    from wingopt.results import write_text_atomic

    path = tmp_path / "new.toml"
    assert write_text_atomic(path, "a = 1\n", what="write-problem") == (path, None)
    with pytest.raises(OutputError, match="write-problem = .*new.toml.*exists.*--force"):
        write_text_atomic(path, "a = 2\n", what="write-problem")
    assert path.read_text() == "a = 1\n"
    _, kept = write_text_atomic(path, "a = 2\n", what="write-problem", force=True)
    assert kept == tmp_path / "new.toml.bak" and kept.read_text() == "a = 1\n" and path.read_text() == "a = 2\n"
    _, kept = write_text_atomic(path, "a = 3\n", what="write-problem", force=True)
    assert kept == tmp_path / "new.toml.bak.1" and kept.read_text() == "a = 2\n"
    assert (tmp_path / "new.toml.bak").read_text() == "a = 1\n"  # the first backup is kept too
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new.toml", "new.toml.bak", "new.toml.bak.1"]
    with pytest.raises(OutputError, match="write-problem.*the input problem"):
        write_text_atomic(path, "x", what="write-problem", inputs=[("problem", str(path))])
    with pytest.raises(OutputError, match="write-problem.*is a directory"):
        write_text_atomic(tmp_path, "x", what="write-problem")
    with pytest.raises(OutputError, match="does not exist"):
        write_text_atomic(tmp_path / "no" / "x.toml", "x", what="write-problem")
