"""The sweep workflow: tasks of a spec, run on an engine, records appended, table and summary written.

Output directory::

    records.jsonl   one JSON record per finished task (appended as tasks finish; resumable)
    table.csv       per case (runs equal but for the seed): mean, std, min, max of each metric
    table.parquet   the same, when pyarrow is installed
    summary.json    spec, counts (tasks, recorded, failed), wall time, engine
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path

from wingopt.errors import OutputError
from wingopt.results import OwnedDirectory
from wingopt.workflows import morph_sweep
from wingopt.workflows.studies import protocol_sign
from wingopt.workflows.sweep.engine import Engine, SharedInput, SweepTask
from wingopt.workflows.sweep.protocol import (
    ORACLE_OFFSETS,
    build_model,
    digest,
    estimator,
    has_oracle,
    protocol_record,
    simulate_clean,
    task_cost,
    task_key,
)
from wingopt.workflows.sweep.records import RecordLog, by_key, summary_rows, write_table
from wingopt.workflows.sweep.spec import SweepSpec

__all__ = ["sweep_tasks", "run_sweep", "METRICS", "run_records"]

log = logging.getLogger(__name__)

METRICS = (
    "load_error",
    "deflection_error",
    "lift_error",
    "lift",
    "true_lift",
    "sign_ok",
    "covered",
    "regularization",
    "oracle_load_error",
    "duration_s",
)
"""Metrics summarised per case (``sign_ok``, ``covered``: the mean is the fraction of runs)."""


def sweep_tasks(spec: SweepSpec) -> tuple[list[SweepTask], list[SharedInput]]:
    """One task per run of ``spec``; truths and models shared between the runs that need the same."""
    tasks, shared = [], {}
    for run in spec.runs:
        model_key = f"model/{digest(run.problem)}"
        # The truth's own mesh is truth_nodes: estimator meshes that differ share one truth.
        tp = run.truth_problem if run.truth_nodes is None else run.truth_problem.with_mesh(run.truth_nodes)
        truth_key = f"truth/{digest(tp, run.load, run.truth_nodes, run.t_end)}/{run.load}"
        shared.setdefault(model_key, SharedInput(model_key, build_model, (run.problem,)))
        args = (run.truth_problem, run.load, run.truth_nodes, run.t_end)
        shared.setdefault(truth_key, SharedInput(truth_key, simulate_clean, args))
        method = run.params["method"]
        offsets = tuple(ORACLE_OFFSETS) if spec.oracle and has_oracle(estimator(method)) else None
        sign = protocol_sign(run.load) * abs(run.problem.identification.initial_load)
        args = (run.params, method, run.noise_fraction, int(run.params["seed"]), run.settings, sign, offsets)
        cost = task_cost(method, run.problem.nodes, run.t_end, bool(offsets))
        tasks.append(SweepTask(task_key(run.params), protocol_record, args, (truth_key, model_key), cost))
    return tasks, list(shared.values())


def run_records(
    tasks: list[SweepTask],
    shared: list[SharedInput],
    records: RecordLog,
    engine: Engine,
    on_record: Callable[[dict], None] | None = None,
    description: str = "sweep",
) -> tuple[dict[str, dict], int]:
    """Run the tasks not yet recorded (successfully) in ``records``; returns (record by key, tasks run).

    Each record is appended as its task finishes, before ``on_record`` sees it.
    """
    done = {k for k, r in by_key(records.read()).items() if r.get("status", "ok") == "ok"}
    todo = [t for t in tasks if t.key not in done]
    if done:
        log.info("%d of %d tasks already recorded, %d to run", len(tasks) - len(todo), len(tasks), len(todo))
    for rec in engine.run(todo, shared, description):
        records.append(rec)
        if on_record:
            on_record(rec)
    return by_key(records.read()), len(todo)


def run_sweep(
    spec: SweepSpec,
    out: str | Path,
    engine: Engine,
    resume: bool = False,
    on_record: Callable[[dict], None] | None = None,
) -> dict:
    """Run ``spec`` on ``engine`` into ``out`` (see the module docstring); returns the summary.

    ``out`` is an :class:`~wingopt.results.OwnedDirectory` (the ownership rule of
    :mod:`wingopt.results.ownership`: empty, new, or holding only what wingopt wrote there; the
    spec and the problem file outside it): a user's ``records.jsonl`` is never appended to or cut.
    """
    owner = OwnedDirectory(out, inputs=spec_inputs(spec))
    path = owner.path / "records.jsonl"
    if not resume and path.exists() and path.stat().st_size:
        raise OutputError(f"out = {str(out)!r}: records.jsonl exists; use --resume to continue it or another --out")
    records = RecordLog(path, fresh=not resume, owner=owner)
    morph = getattr(spec, "kind", None) == morph_sweep.KIND  # morphing robustness (issue 34)
    tasks, shared = morph_sweep.morph_tasks(spec) if morph else sweep_tasks(spec)
    t0 = time.perf_counter()
    by, ran = run_records(tasks, shared, records, engine, on_record)
    mine = [by[t.key] for t in tasks if t.key in by]
    flat = [{**r, **r.get("params", {})} for r in mine]
    rows = morph_sweep.morph_table(mine) if morph else summary_rows(flat, spec.case_fields, METRICS)
    tables = write_table(owner.path / "table", rows, owner)
    failed = [r for r in mine if r.get("status") != "ok"]
    summary = {
        "spec": spec.source,
        "title": spec.title,
        "tasks": len(tasks),
        "ran": ran,
        "recorded": len(mine) - len(failed),
        "failed": [{"key": r["key"], "error": r.get("error")} for r in failed],
        "case_fields": list(spec.case_fields),
        "cases": rows,
        "wall_s": time.perf_counter() - t0,
        "workers": engine.n_workers,
        "mode": engine.settings.mode,
        "tables": [p.name for p in tables],
    }
    owner.write_json("summary.json", summary)
    return summary


def spec_inputs(spec: SweepSpec) -> list[tuple[str, str]]:
    """The files a sweep reads (its spec, its problem files): never inside its output directory."""
    out = [("spec", spec.source)]
    for src in dict.fromkeys(str(r.problem.source) for r in spec.runs):
        out.append(("problem", src))
    return out
