"""``--force`` lifts the time limit of the size estimate (issue 26): ``identify`` and ``demo``, like
``morph``, refuse a run estimated beyond a day of CPU before any work, and run it with ``--force``."""

from __future__ import annotations

import pytest

from wingopt import resources
from wingopt.cli import main
from wingopt.membrane import MembraneModel
from wingopt.problem import PROBLEMS_DIR

LINEAR_FAST = ["--model", "linear", "--no-model-form", "--window", "100", "--stride", "50", "--modes", "20",
               "--truth-mesh", "25x13", "--t-end", "0.3", "--no-plots"]  # fmt: skip


def _no_model(*args, **kwargs):
    raise AssertionError("a model was built before the resource check")


def _too_long(*args, **kwargs) -> resources.Estimate:
    """An estimate beyond the limit in time only (the memory fits)."""
    return resources.Estimate("a mocked run", 2e8, 3 * resources.MAX_SECONDS, {"trajectory": 1.0},
                              {"trajectory": "--t-end 1e7"})  # fmt: skip


@pytest.fixture
def small_file(tmp_path):
    src = (PROBLEMS_DIR / "membrane.toml").read_text().replace("nodes = [25, 13]", "nodes = [13, 7]")
    path = tmp_path / "small.toml"
    path.write_text(src)
    return path


def test_identify_refuses_a_run_beyond_the_time_limit_unless_forced(small_file, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(resources, "estimate_identify", _too_long)
    argv = ["identify", str(small_file), "--load", "L1", *LINEAR_FAST]
    with monkeypatch.context() as m:  # the refusal comes before any work: no model is built
        m.setattr(MembraneModel, "from_problem", classmethod(_no_model))
        assert main(argv + ["--out", str(tmp_path / "refused")]) == 2
    err = capsys.readouterr().err
    assert "limit of 1 day" in err and "or --force to run it anyway" in err and "--t-end 1e7" in err
    assert not (tmp_path / "refused").exists()
    assert main(argv + ["--out", str(tmp_path / "forced"), "--force"]) == 0
    assert (tmp_path / "forced" / "summary.json").exists()


def test_demo_refuses_a_run_beyond_the_time_limit_unless_forced(tmp_path, monkeypatch, capsys):
    import wingopt.workflows.demo as demo
    import wingopt.workflows.demo_report as demo_report

    def run_demo(out, cfg, progress=None):  # the demo's own checks, without its 21 runs
        resources.check(_too_long(), max_memory=1e15)
        return {"forced": True}

    monkeypatch.setattr(demo, "run_demo", run_demo)
    monkeypatch.setattr(demo_report, "summary_table", lambda summary: "table")
    assert main(["demo", "--quick", "--out", str(tmp_path / "d")]) == 2
    assert "or --force to run it anyway" in capsys.readouterr().err
    assert main(["demo", "--quick", "--out", str(tmp_path / "d"), "--force"]) == 0
    assert "table" in capsys.readouterr().out


def test_force_is_the_shared_option():
    from wingopt.cli.options import SHARED

    assert SHARED["--force"]["action"] == "store_true"
    with resources.long_runs(False, "--force"), pytest.raises(Exception, match="--force"):
        resources.check(_too_long(), max_memory=1e15)
