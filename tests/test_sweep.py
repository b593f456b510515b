"""The study engine (issue 14): same records serially and on a dask cluster, worker deaths,
interrupt and resume, torn record lines, the BLAS thread cap, the spec reader and the CLI.

Small protocol runs: estimator 13x7, truth 25x13, 0.2 s. One 2-worker LocalCluster for the module.
"""

import json
import logging
import os
import signal
import sys
import time
from pathlib import Path

import cloudpickle
import pytest
from threadpoolctl import threadpool_limits

from wingopt.cli import main
from wingopt.errors import InputError
from wingopt.estimation.options import IdentifyOptions
from wingopt.estimation.registry import resolve
from wingopt.estimation.runners import run_record
from wingopt.workflows.protocols import simulate_case
from wingopt.workflows.studies import evaluate, protocol_sign
from wingopt.workflows.sweep.engine import Engine, EngineSettings, SweepTask, blas_threads
from wingopt.workflows.sweep.records import TIMING_FIELDS, RecordLog, by_key, read_records
from wingopt.workflows.sweep.run import run_records, run_sweep, sweep_tasks
from wingopt.workflows.sweep.spec import load_spec, parse_spec

# The workers unpickle this module's task functions by value (it is not importable there).
cloudpickle.register_pickle_by_value(sys.modules[__name__])

ROOT = Path(__file__).resolve().parents[1]

SPEC = """
problem = "{problem}"
truth_mesh = "25x13"
t_end = 0.2
"truth.material.prestrain" = 0.0
[grid]
load = ["L1"]
noise = [1]
seed = [0, 1]
method = ["mhe", "jekf-tuned"]
"mesh.nodes" = [[13, 7]]
"""


@pytest.fixture(scope="module")
def cluster():
    """A 2-worker LocalCluster (processes, 1 thread each), shared by this module's tests."""
    with Engine(EngineSettings(mode="local", workers=2, progress=False, dashboard=False)) as eng:
        yield eng


@pytest.fixture
def spec_file(tmp_path):
    path = tmp_path / "study.toml"
    text = SPEC.format(problem=ROOT / "problems" / "membrane.toml")
    path.write_text(text.replace('"truth.material.prestrain" = 0.0\n', ""))
    return path


def results_only(records):
    """Records without timings and process ids, sorted by key."""
    return sorted(({k: v for k, v in r.items() if k not in TIMING_FIELDS} for r in records), key=lambda r: r["key"])


@pytest.fixture
def one_blas_thread():
    """This process computes with one BLAS thread, as the workers do (BLAS_ENV): multithreaded BLAS sums
    in another order (1e-10 apart) when pytest runs without make test's thread caps."""
    with threadpool_limits(1):
        yield


def test_serial_and_cluster_records_are_identical_and_match_the_direct_computation(
    spec_file, tmp_path, cluster, one_blas_thread
):
    spec = load_spec(spec_file)
    assert len(spec.runs) == 4 and spec.case_fields == ("method",)
    with Engine(EngineSettings(mode="serial", progress=False)) as serial:
        s1 = run_sweep(spec, tmp_path / "serial", serial)
    s2 = run_sweep(spec, tmp_path / "cluster", cluster)
    assert s1["recorded"] == s2["recorded"] == 4 and not s1["failed"] and not s2["failed"]
    r1 = read_records(tmp_path / "serial" / "records.jsonl")
    r2 = read_records(tmp_path / "cluster" / "records.jsonl")
    assert {r["pid"] for r in r2} - {os.getpid()}, "cluster records must come from worker processes"
    assert results_only(r1) == results_only(r2)  # identical numbers, to the last bit
    # The one way in: the registry's estimator on the same record, as identify --load runs it.
    run = spec.runs[0]
    case = simulate_case(
        run.truth_problem, "L1", 0.01, run.params["seed"], run.truth_nodes, run.t_end, tell_noise=False
    )
    from wingopt.membrane import MembraneModel

    model = MembraneModel.from_problem(run.problem)
    spec_ = resolve(run.params["method"], simulated="linear")
    options = IdentifyOptions(initial_load=protocol_sign("L1") * 200.0)
    res = run_record(spec_, model, case.measurements, options, truth=case, settings=run.settings)
    direct = evaluate(case, res, model, run.params["method"])
    mine = next(r for r in r1 if r["params"] == run.params)
    assert mine["load_error"] == direct.load_error and mine["lift"] == direct.lift
    assert 0.005 < direct.load_error < 0.05
    table = (tmp_path / "cluster" / "table.csv").read_text().splitlines()
    assert table[0].startswith("method,runs,failed,load_error_mean") and len(table) == 3


def test_blas_is_capped_to_one_thread_in_the_workers(cluster):
    info = cluster.run_on_workers(blas_threads)
    assert len(info) == 2
    for worker in info.values():
        assert worker["pools"] and all(p["threads"] == 1 for p in worker["pools"])
        assert worker["env"]["OPENBLAS_NUM_THREADS"] == "1" and worker["env"]["OMP_NUM_THREADS"] == "1"


def _die_once(marker: str, i: int) -> dict:
    """Task ``i`` kills its own worker process the first time it runs (``marker`` records that)."""
    if i == 2 and not os.path.exists(marker):
        Path(marker).write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGKILL)
    return {"i": i, "square": i * i}


def _hang_once(marker: str, i: int) -> dict:
    """Task ``i`` hangs (60 s) the first time it runs: a task its worker holds without progress."""
    if i == 1 and not os.path.exists(marker):
        Path(marker).write_text(str(os.getpid()))
        time.sleep(60)
        return {"i": i, "attempt": "first"}
    return {"i": i, "attempt": "again" if i == 1 else "only"}


def test_a_stalled_task_is_submitted_again_on_another_worker(tmp_path):
    """No task finished for ``stall_s``: the held task is cancelled and run again elsewhere."""
    marker = str(tmp_path / "hung")
    tasks = [SweepTask(f"t{i}", _hang_once, (marker, i), cost=10 - i) for i in range(3)]
    settings = EngineSettings(mode="local", workers=2, progress=False, dashboard=False, stall_s=8.0)
    t0 = time.perf_counter()
    with Engine(settings) as eng:
        records = {r["key"]: r for r in eng.run(tasks)}
    assert time.perf_counter() - t0 < 50  # did not wait for the 60 s hang
    assert all(r["status"] == "ok" for r in records.values()) and len(records) == 3
    assert records["t1"]["attempt"] == "again" and records["t1"]["pid"] != int(Path(marker).read_text())


def test_a_worker_killed_mid_sweep_is_replaced_and_every_record_is_present(cluster, tmp_path):
    marker = str(tmp_path / "killed")
    tasks = [SweepTask(f"t{i}", _die_once, (marker, i), cost=10 - i) for i in range(6)]
    log = RecordLog(tmp_path / "records.jsonl", fresh=True)
    by, ran = run_records(tasks, [], log, cluster)
    assert ran == 6 and os.path.exists(marker)
    assert sorted(r["i"] for r in by.values()) == list(range(6))
    assert all(r["status"] == "ok" and r["square"] == r["i"] ** 2 for r in by.values())
    assert by["t2"]["pid"] != int(Path(marker).read_text())  # re-run on a live worker


def test_a_worker_death_costs_no_retries(tmp_path):
    """With no retries at all, a task whose worker dies under it still runs again and is recorded:
    a worker's death is not the task's failure (it has a budget of its own, engine.MAX_WORKER_DEATHS)."""
    marker = str(tmp_path / "killed")
    tasks = [SweepTask(f"t{i}", _die_once, (marker, i), cost=10 - i) for i in range(4)]
    settings = EngineSettings(mode="local", workers=2, retries=0, progress=False, dashboard=False)
    with Engine(settings) as eng:
        records = {r["key"]: r for r in eng.run(tasks)}
    assert os.path.exists(marker) and sorted(records) == [f"t{i}" for i in range(4)]
    assert all(r["status"] == "ok" and r["square"] == r["i"] ** 2 for r in records.values()), records


def test_two_local_clusters_run_side_by_side_without_a_port_clash(cluster):
    """The scheduler serves HTTP routes even without a dashboard, by default on port 8787: a second
    cluster beside the first (two sweeps, two test workers) took another port with a UserWarning."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        with Engine(EngineSettings(mode="local", workers=1, progress=False, dashboard=False)) as eng:
            assert eng.dashboard_link is None and eng.n_workers == 1
            assert eng.client.submit(pow, 3, 2).result() == 9


def _count(counter: str, i: int, run: int = 1) -> dict:
    """A task that appends ``run:index`` to ``counter`` each time it runs."""
    with open(counter, "a") as fh:
        fh.write(f"{run}:{i}\n")
    return {"i": i}


def _always_fails(counter: str) -> dict:
    _count(counter, -1)
    raise RuntimeError("no convergence")


class Stop(Exception):
    pass


@pytest.mark.parametrize("mode", ["serial", "cluster"])
def test_an_interrupted_sweep_resumes_without_recomputing_a_recorded_task(mode, cluster, tmp_path):
    counter = tmp_path / "executions.txt"
    path = tmp_path / "records.jsonl"

    def tasks(run):
        return [SweepTask(f"t{i}", _count, (str(counter), i, run)) for i in range(8)]

    def stop_after_3(rec, seen=[]):  # noqa: B006 - the counter of this call
        seen.append(rec)
        if len(seen) == 3:
            raise Stop

    with Engine(EngineSettings(mode="serial", progress=False)) as serial:
        engine = serial if mode == "serial" else cluster
        with pytest.raises(Stop):
            run_records(tasks(1), [], RecordLog(path, fresh=True), engine, stop_after_3)
        first = {r["key"] for r in read_records(path)}
        assert len(first) == 3
        by, ran = run_records(tasks(2), [], RecordLog(path), engine)
    assert ran == 8 - 3 and sorted(by) == [f"t{i}" for i in range(8)]
    runs = [line.split(":") for line in counter.read_text().split()]
    second = [f"t{i}" for r, i in runs if r == "2"]
    # Run 2 ran exactly the 5 tasks without a record, each once; no recorded task ran again.
    assert sorted(second) == sorted(set(by) - first)
    if mode == "serial":
        assert sorted(f"t{i}" for r, i in runs if r == "1") == sorted(first)  # nothing ran but what was recorded
    # (on the cluster a task in flight at the interruption may still finish unrecorded: it runs again)


def test_a_task_failing_every_retry_is_recorded_as_a_failure(tmp_path):
    counter = tmp_path / "n.txt"
    tasks = [SweepTask("bad", _always_fails, (str(counter),)), SweepTask("good", _count, (str(counter), 1))]
    with Engine(EngineSettings(mode="serial", retries=2, progress=False)) as eng:
        by, _ = run_records(tasks, [], RecordLog(tmp_path / "r.jsonl", fresh=True), eng)
    assert by["bad"]["status"] == "failed" and "RuntimeError: no convergence" in by["bad"]["error"]
    assert by["good"]["status"] == "ok" and counter.read_text().split().count("1:-1") == 3  # 1 + 2 retries


def test_a_torn_last_line_is_ignored_with_a_warning_and_cut_before_appending(tmp_path, caplog):
    path = tmp_path / "records.jsonl"
    good = [{"key": "a", "status": "ok", "x": 1.5}, {"key": "b", "status": "ok", "x": 2.5}]
    path.write_text("".join(json.dumps(r) + "\n" for r in good) + '{"key": "c", "stat')
    with caplog.at_level(logging.WARNING):
        assert read_records(path) == good
    assert "torn last line" in caplog.text
    log = RecordLog(path)
    log.append({"key": "c", "status": "ok", "x": 3.5})
    assert [r["key"] for r in read_records(path)] == ["a", "b", "c"]
    assert path.read_text().endswith("\n") and path.read_text().count("\n") == 3
    path.write_text('{"key": "a"}\nnot json\n{"key": "b"}\n')
    with pytest.raises(InputError, match="line 2"):
        read_records(path)
    assert by_key([{"key": "a", "status": "failed"}, {"key": "a", "status": "ok", "v": 1}])["a"]["v"] == 1


@pytest.mark.parametrize(
    "extra, match",
    [
        ('method = "kalman"', "method = 'kalman': expected one of auto, mhe"),
        ('"material.prestrain" = -0.01', "prestrain = -0.01: expected a number in \\[1e-09, 0.5\\]"),
        ('"estimator.windw" = 100', "estimator.windw = 100: expected an MHESettings field"),
        ("noise = 250", "noise = 250: expected a noise level in percent"),
        ('load = "L9"', "load = 'L9': expected one of L1"),
    ],
)
def test_spec_errors_are_one_line_naming_the_field(extra, match):
    data = {"problem": "membrane", "grid": {"seed": [0]}}
    key, value = (s.strip() for s in extra.split("=", 1))
    data["grid"]["load"] = ["L1"]
    data["grid"][key.strip('"')] = [json.loads(value)]
    with pytest.raises(InputError, match=match) as err:
        parse_spec(data, "study.toml")
    assert "\n" not in str(err.value) and str(err.value).startswith("study.toml")
    with pytest.raises(InputError, match="colour = 'red': expected one of the spec keys"):
        parse_spec({"problem": "membrane", "colour": "red"}, "study.toml")


def test_spec_cases_cross_the_grid_and_overrides_reach_truth_and_estimator():
    data = {
        "problem": "membrane",
        "grid": {"seed": [0, 1], "truth.material.prestrain": [0.04, 0.06]},
        "cases": [{"load": "L1", "estimator.window": 100}, {"load": "L3"}],
    }
    spec = parse_spec(data)
    assert len(spec.runs) == 8 and set(spec.case_fields) == {"truth.material.prestrain", "load", "estimator.window"}
    run = spec.runs[1]
    assert run.truth_problem.material.prestrain == 0.06 and run.problem.material.prestrain == 0.05
    assert run.settings.window == 100 and spec.runs[-1].settings.window != 100
    # Shared inputs: one truth per (truth problem, load), one model per estimator problem; estimator
    # meshes share the truth (simulated on truth_mesh).
    data["grid"]["mesh.nodes"] = [[13, 7], [25, 13]]
    tasks, shared = sweep_tasks(parse_spec(data))
    kinds = [s.key.split("/")[0] for s in shared]
    assert len(tasks) == 16 and kinds.count("truth") == 4 and kinds.count("model") == 2


def test_sweep_command_serial_then_resume_on_an_attached_scheduler(spec_file, tmp_path, cluster, capsys):
    out = tmp_path / "run"
    spec_file.write_text(spec_file.read_text().replace('["mhe", "jekf-tuned"]', '["mhe"]'))
    assert main(["sweep", str(spec_file), "--out", str(out), "--serial"]) == 0
    assert "2 of 2 tasks recorded (2 run now, 0 failed)" in capsys.readouterr().out
    # Running again into the same place without --resume would lose the records: refused.
    assert main(["sweep", str(spec_file), "--out", str(out), "--serial"]) == 2
    address = cluster.client.scheduler.address
    assert main(["sweep", str(spec_file), "--out", str(out), "--resume", "--scheduler", address, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert summary["ran"] == 0 and summary["recorded"] == 2 and summary["mode"] == "scheduler"
    assert main(["sweep", str(tmp_path / "missing.toml"), "--out", str(out)]) == 2


def test_compare_resumes_the_records_of_the_pre_engine_compare(tmp_path, capsys):
    """Records without a key (written by compare before the engine) are matched by their fields,
    in a records file wingopt wrote (listed in the directory's manifest); the same file edited
    by hand is no longer wingopt's: --resume refuses it, naming it, and leaves it as it is."""
    from wingopt.results.ownership import manifest_entry, read_manifest, write_manifest

    problem = tmp_path / "small.toml"
    problem.write_text((ROOT / "problems" / "membrane.toml").read_text().replace("nodes = [25, 13]", "nodes = [13, 7]"))
    out = tmp_path / "cmp"
    argv = ["compare", str(problem), "--loads", "L1", "--noise", "5", "--n-seeds", "1", "--methods", "mhe"]
    argv += ["--no-oracle", "--truth-mesh", "25x13", "--out", str(out), "--json"]
    assert main(argv) == 0
    first = json.loads(capsys.readouterr().out.splitlines()[-1])
    path = out / "records.jsonl"
    old = [{k: v for k, v in r.items() if k not in ("key", "status", "params")} for r in read_records(path)]
    text = "".join(json.dumps(r) + "\n" for r in old)
    path.write_text(text)
    assert main(argv + ["--resume"]) == 2
    assert "records.jsonl" in capsys.readouterr().err and path.read_text() == text
    files = read_manifest(out)["files"]
    files["records.jsonl"] = {"log": True, **manifest_entry(path)}  # as the older compare's own file
    write_manifest(out, files)
    assert main(argv + ["--resume"]) == 0
    again = json.loads(capsys.readouterr().out.splitlines()[-1])
    recs = read_records(path)
    assert len(recs) == 1 and recs[0]["key"] == '{"load":"L1","method":"mhe","noise":0.05,"seed":0}'
    assert again["comparison"][0]["load_error"] == first["comparison"][0]["load_error"]


def test_a_batch_cluster_without_dask_jobqueue_names_the_extra(spec_file, tmp_path, capsys):
    pytest.importorskip("distributed")
    try:
        import dask_jobqueue  # noqa: F401
    except ImportError:
        pass
    else:
        pytest.skip("dask-jobqueue is installed")
    assert main(["sweep", str(spec_file), "--out", str(tmp_path / "x"), "--cluster", "slurm"]) == 2
    err = capsys.readouterr().err.strip()
    assert "pip install 'wingopt[cluster]'" in err and len(err.splitlines()) == 1
