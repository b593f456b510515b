"""One way in: ``identify`` reads one data source, and the simulated case's options exist only on it."""

from pathlib import Path

import numpy as np
import pytest

import wingopt as wo
from wingopt.cli import main
from wingopt.errors import InputError
from wingopt.workflows.sources import SIMULATION_ONLY, DICRecord, MeasuredRecord, SimulatedCase, data_source

DATA = Path(__file__).parents[1] / "examples" / "data"
RECORD = DATA / "tunnel_300Hz.csv"
SHORT = {"t_end": 0.2, "truth_nodes": (19, 10)}

SIMULATION_FLAGS = [
    ["--noise", "2"],
    ["--seed", "3"],
    ["--truth", "fvk"],
    ["--truth-mesh", "25x13"],
    ["--truth-prestrain", "0.05", "0.04"],
    ["--truth-damping", "2"],
    ["--t-end", "0.3"],
    ["--gust"],
    ["--same-mesh"],
]


@pytest.mark.parametrize("flag", SIMULATION_FLAGS, ids=lambda f: f[0])
@pytest.mark.parametrize("source", ["--data", "--dic"])
def test_a_simulation_option_with_measured_data_is_refused_by_name(flag, source, tmp_path, capsys):
    data = str(RECORD if source == "--data" else DATA / "tunnel_dic_300Hz.npz")
    code = main(["identify", "membrane", source, data, *flag, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and flag[0] in err[0] and "simulation-only" in err[0] and source in err[0]
    assert not (tmp_path / "out").exists()


def test_the_refusal_names_every_simulation_option_given(tmp_path, capsys):
    argv = ["identify", "membrane", "--data", str(RECORD), "--noise", "5", "--seed", "2", "--gust"]
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    line = capsys.readouterr().err.strip()
    assert all(name in line for name in ("--noise", "--seed", "--gust"))


@pytest.mark.parametrize("name", sorted(SIMULATION_ONLY))
def test_the_api_refuses_a_simulation_option_with_data(name):
    value = {"truth": "fvk", "truth_nodes": (25, 13), "truth_prestrain": (0.05, 0.04), "gust": object()}.get(name, 2)
    with pytest.raises(InputError, match=rf"^{name} \({SIMULATION_ONLY[name]}\): simulation-only"):
        wo.identify("membrane", data=str(RECORD), **{name: value})


def test_one_source_only():
    with pytest.raises(InputError, match="exactly one of"):
        data_source(load="L1", data=str(RECORD))
    with pytest.raises(InputError, match="exactly one of"):
        data_source()
    with pytest.raises(InputError, match="give the data once"):
        wo.identify("membrane", MeasuredRecord(str(RECORD)), load="L1")
    with pytest.raises(InputError, match="channels"):
        data_source(dic="frames.npz", channels=object())


def test_sources_are_the_shorthands():
    assert data_source(load="L2", seed=4) == SimulatedCase("L2", seed=4)
    assert data_source(load="L2", truth_nodes=None).truth_nodes is None  # the seed's same-mesh protocol
    assert data_source(data="x.csv") == MeasuredRecord("x.csv")
    assert data_source(dic="frames") == DICRecord("frames")
    with pytest.raises(InputError, match="load = 'L9'"):
        SimulatedCase("L9")
    with pytest.raises(InputError, match="t_end"):
        SimulatedCase("L1", t_end=-1.0)


def test_a_source_object_gives_the_shorthands_answer():
    problem = wo.load_problem("membrane").with_mesh((13, 7))
    by_keywords = wo.identify(problem, load="L1", method="mhe", seed=1, **SHORT)
    by_source = wo.identify(problem, SimulatedCase("L1", seed=1, **SHORT), method="mhe")
    np.testing.assert_array_equal(by_keywords.result.lift, by_source.result.lift)
    assert by_keywords.summary()["seed"] == by_source.summary()["seed"] == 1


def _sweep_spec(methods):
    from wingopt.workflows.sweep.spec import parse_spec

    grid = {"load": ["L1"], "seed": [0], "method": methods, "mesh.nodes": [[13, 7]]}
    return parse_spec({"problem": "membrane", "truth_mesh": "19x10", "t_end": 0.2, "grid": grid})


def test_a_sweep_runs_the_registry_estimators_auto_included(tmp_path):
    from wingopt.workflows.sweep.engine import Engine, EngineSettings
    from wingopt.workflows.sweep.run import run_sweep

    spec = _sweep_spec(["auto", "mhe"])
    with Engine(EngineSettings(mode="serial", progress=False)) as engine:
        summary = run_sweep(spec, tmp_path / "sweep", engine)
    assert summary["recorded"] == 2 and not summary["failed"]
    from wingopt.workflows.sweep.records import read_records

    records = {r["params"]["method"]: r for r in read_records(tmp_path / "sweep" / "records.jsonl")}
    # auto on the protocol's simulated (linear) truth is the linear MHE, as identify --load resolves it
    assert records["auto"]["lift"] == records["mhe"]["lift"] and records["auto"]["load_error"] < 0.2


def test_a_sweep_refuses_an_estimator_of_frames_or_streams():
    with pytest.raises(InputError, match="method.*fullfield.*DIC frames"):
        _sweep_spec(["fullfield"])
    with pytest.raises(InputError, match="method.*ekf"):
        _sweep_spec(["ekf"])
