"""Resource checks before work (issue 12): absurd sizes are refused up front (no model is built), with the estimate."""

import pytest

import wingopt as wo
from wingopt import resources
from wingopt.cli import main
from wingopt.errors import InputError
from wingopt.membrane import MembraneModel
from wingopt.plate import PlateModel
from wingopt.problem import PROBLEMS_DIR, load_problem


def test_dof_counts_match_the_models():
    membrane, plate = load_problem("membrane"), load_problem("plate")
    assert MembraneModel.from_problem(membrane, (13, 7)).n == resources.membrane_dofs((13, 7))
    assert PlateModel.from_problem(plate, (7, 31)).n == resources.plate_dofs((7, 31))


def test_estimate_of_a_normal_run_is_modest_and_of_absurd_runs_huge():
    small = resources.estimate_identify((25, 13), 1001, truth_nodes=(49, 25))
    assert 0.15e9 < small.memory < 0.6e9  # 233 MB peak RSS measured
    assert resources.estimate_identify((2000, 2000), 1001).memory > 1e12
    assert resources.estimate_identify((25, 13), 10**9 + 1, truth_nodes=(49, 25)).memory > 1e13
    assert resources.estimate_morph((13, 61), 1e6, 0.01).memory > 1e12
    assert 0.25e9 < resources.estimate_morph((13, 61), 0.5, 0.01).memory < 0.6e9  # 397 MB peak RSS measured


def _no_model_built(monkeypatch) -> None:
    """Building a membrane or plate model fails the test: a refusal comes before any work (a time
    bound would say the same on an idle machine only)."""

    def refuse(*args, **kwargs):
        raise AssertionError("a model was built before the resource check")

    monkeypatch.setattr(MembraneModel, "from_problem", classmethod(refuse))
    monkeypatch.setattr(PlateModel, "from_problem", classmethod(refuse))


@pytest.mark.parametrize(
    "argv",
    [
        ["identify", "membrane", "--load", "L1", "--mesh", "2000x2000"],
        ["identify", "membrane", "--load", "L1", "--t-end", "1e4"],
        ["identify", "membrane", "--load", "L1", "--t-end", "1e6"],
        ["morph", "plate", "--shape", "twist", "--t-end", "1e6"],
        ["morph", "plate", "--shape", "twist", "--t-end", "1e4"],
        ["morph", "plate", "--shape", "twist", "--mesh", "2000x2000"],
        ["identify", "membrane", "--load", "L1", "--max-memory", "10M"],
    ],
)
def test_cli_refuses_up_front_with_the_estimate(argv, tmp_path, capsys, monkeypatch):
    _no_model_built(monkeypatch)
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "needs about" in err and ("available" in err or "--max-memory" in err), err
    assert not (tmp_path / "o").exists()


def test_problem_file_mesh_is_checked_too(tmp_path, capsys, monkeypatch):
    src = (PROBLEMS_DIR / "membrane.toml").read_text().replace("nodes = [25, 13]", "nodes = [2000, 2000]")
    (tmp_path / "big.toml").write_text(src)
    _no_model_built(monkeypatch)
    assert main(["identify", str(tmp_path / "big.toml"), "--load", "L1", "--out", str(tmp_path / "o")]) == 2
    assert "2000x2000" in capsys.readouterr().err


def test_api_refuses_with_input_error():
    with pytest.raises(InputError, match="needs about"):
        wo.identify("membrane", load="L1", t_end=1e6)
    with pytest.raises(InputError, match="needs about"):
        wo.morph(load_problem("plate"), "twist", "lqr", t_end=1e6)
    with pytest.raises(InputError, match="--max-memory"):
        wo.identify("membrane", load="L1", max_memory=1e6)


def test_parse_size():
    assert resources.parse_size("4G") == 4e9 and resources.parse_size("500MB") == 5e8
    with pytest.raises(InputError, match="max-memory"):
        resources.parse_size("lots")
