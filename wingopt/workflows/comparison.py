"""The estimator studies as sweeps on the study engine: the comparison table, sign and band, consistency.

Each study is a list of independent tasks (:mod:`wingopt.workflows.sweep.protocol`) run by the
engine (serial, a local cluster, or a scheduler); the per-case pieces (simulated cases, running a
method, scoring it) are in :mod:`wingopt.workflows.studies`.

:func:`run_comparison` is the ``wingopt compare`` preset (:class:`ComparisonPreset`): L1–L3 x noise
levels x seeds for the chosen methods (the MHE with its oracle lambda), the sign and band study and
the consistency study as one task list, recorded in ``DIR/records.jsonl`` as they finish (a study
resumes where it stopped), then the report (:mod:`wingopt.workflows.comparison_report`).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

from wingopt.errors import InputError, SolverError
from wingopt.estimation.mhe import MHESettings
from wingopt.estimation.options import IdentifyOptions
from wingopt.estimation.registry import resolve
from wingopt.estimation.runners import settings_for
from wingopt.problem import load_problem
from wingopt.problem.membrane import MembraneProblem
from wingopt.results import OwnedDirectory, check_new_file, check_writable, write_text_atomic
from wingopt.workflows.comparison_preset import JEKF_MODES, LOADS, ComparisonPreset
from wingopt.workflows.comparison_report import (
    checklist_markdown,
    consistency_markdown,
    doc_header,
    oracle_markdown,
    sign_markdown,
)
from wingopt.workflows.protocols import TRUTH_NODES
from wingopt.workflows.studies import (
    METHODS,
    ORACLE_OFFSETS,
    CaseRecord,
    comparison_markdown,
    record_from_dict,
    summarize,
)
from wingopt.workflows.sweep.engine import Engine, EngineSettings
from wingopt.workflows.sweep.protocol import (
    consistency_rows,
    consistency_tasks,
    protocol_tasks,
    run_tasks,
    task_key,
)
from wingopt.workflows.sweep.records import RecordLog, read_records
from wingopt.workflows.sweep.run import run_records

__all__ = ["comparison_study", "sign_and_band_study", "consistency_study", "ComparisonPreset", "run_comparison"]
__all__ += ["LOADS", "JEKF_MODES", "write_overlays"]


def comparison_study(
    problem: MembraneProblem,
    loads: Sequence[str] = ("L1", "L2", "L3"),
    noises: Sequence[float] = (0.01, 0.05),
    seeds: Iterable[int] = range(5),
    methods: Sequence[str] = METHODS,
    mhe_settings: MHESettings | None = None,
    truth_nodes: tuple[int, int] | None = TRUTH_NODES,
    oracle: bool = True,
    oracle_offsets: Sequence[float] = ORACLE_OFFSETS,
    done: Sequence[CaseRecord] = (),
    jobs: int = 1,
    on_record: Callable[[CaseRecord], None] | None = None,
    engine=None,
) -> list[CaseRecord]:
    """Run every method on every case; one :class:`CaseRecord` per (case, seed, method).

    ``oracle``: also find the MHE's oracle lambda per case (least final load error given the
    truth) on ``chosen lambda * 10**oracle_offsets``, to report the gap to the data-only rule.
    ``done``: records already computed (skipped, returned with the new ones). ``jobs``: worker
    processes of a local dask cluster (1: this process), or ``engine``: an entered
    :class:`~wingopt.workflows.sweep.engine.Engine`. ``on_record`` is called with every new record.
    """
    settings = mhe_settings or MHESettings()
    runs = [(ld, float(nz), int(sd), m) for ld in loads for nz in noises for sd in seeds for m in methods]
    tasks, shared = protocol_tasks(problem, runs, settings, truth_nodes, oracle, oracle_offsets)
    have = {task_key({"load": r.load, "noise": r.noise, "seed": r.seed, "method": r.method}) for r in done}
    tasks = [t for t in tasks if t.key not in have]
    records = list(done)
    for d in run_tasks(tasks, shared, jobs, engine):
        rec = record_from_dict(d)
        records.append(rec)
        if on_record:
            on_record(rec)
    return records


def sign_and_band_study(
    problem: MembraneProblem,
    loads: Sequence[str] = ("L1", "L2", "L3"),
    noise: float = 0.05,
    seeds: Iterable[int] = range(20),
    mhe_settings: MHESettings | None = None,
    truth_nodes: tuple[int, int] | None = TRUTH_NODES,
    done: Sequence[CaseRecord] = (),
    jobs: int = 1,
    on_record: Callable[[CaseRecord], None] | None = None,
) -> list[CaseRecord]:
    """MHE only, many noise seeds: sign right and lift band coverage per load (records as above)."""
    return comparison_study(
        problem, loads, (noise,), seeds, ("mhe",), mhe_settings, truth_nodes, False, (), done, jobs, on_record
    )


def consistency_study(
    problem: MembraneProblem,
    layouts: Sequence[tuple[int, int] | None] = (None, (4, 3), (8, 4)),
    noise: float = 0.01,
    seeds: Iterable[int] = range(3),
    mhe_settings: MHESettings | None = None,
    truth_nodes: tuple[int, int] | None = TRUTH_NODES,
    progress: Callable[[str], None] | None = None,
    jobs: int = 1,
    engine=None,
) -> list[dict]:
    """Consistency load with the problem's 4 sensors (``None``) and sensor grids; error per layout."""
    tasks, shared = consistency_tasks(problem, layouts, noise, seeds, mhe_settings, truth_nodes)
    records = run_tasks(tasks, shared, jobs, engine)
    order = {t.key: i for i, t in enumerate(tasks)}
    rows = consistency_rows(sorted(records, key=lambda r: order[r["key"]]))
    for row in rows:
        if progress:
            progress(f"consistency, {row['sensors']} sensors: load error {row['load_error_mean']:.4f}")
    return rows


def _keyed(rec: dict) -> dict:
    """A record of the compare before the study engine carries no key: derive it from its fields."""
    if "key" not in rec and "load" in rec:
        fields = {"load": rec["load"], "noise": rec["noise"], "seed": rec["seed"], "method": rec["method"]}
        rec = {**rec, "key": task_key(fields), "status": "ok"}
    return rec


def run_comparison(
    problem: str | Path,
    out: str | Path,
    preset: ComparisonPreset,
    engine: EngineSettings,
    *,
    resume: bool = False,
    doc: str | Path | None = None,
    force: bool = False,
    on_start: Callable[[Engine], None] | None = None,
    on_record: Callable[[dict], None] | None = None,
) -> tuple[dict, str]:
    """Run ``preset`` on the membrane ``problem`` on the study engine into the directory ``out``.

    The engine (``engine``: where the tasks run) starts once the problem is read and the tasks
    are built, and ``on_start`` sees it. Records go to ``out/records.jsonl`` as the tasks finish
    (``resume``: keep those there and run only the others; otherwise the file is started afresh),
    each seen by ``on_record``; the consistency rows are kept in ``out/consistency.json``. Writes
    ``summary.json`` and ``comparison.md`` (and the document ``doc`` with its header) atomically.
    ``out`` follows the ownership rule (:mod:`wingopt.results.ownership`: it may hold only what
    wingopt wrote there, unchanged, and not the problem file); ``doc`` onto an existing file is
    refused unless ``force`` (the earlier file is then kept as ``NAME.bak``). Both are checked
    before any work. Returns the report (the summary) and the markdown text; a
    :class:`~wingopt.errors.SolverError` if a task failed.
    """
    prob = load_problem(problem)
    if prob.kind != "membrane":
        raise InputError(f"problem = {str(problem)!r}: compare needs a membrane problem")
    inputs = [("problem", str(prob.source))]
    check_writable(out, inputs=[*inputs, ("--doc", doc)])
    if doc:
        check_new_file(doc, "doc", force=force, inputs=inputs)
    _check_size(prob, preset)
    owner = OwnedDirectory(out, inputs=[*inputs, ("--doc", doc)])
    out = owner.path
    records = _record_log(owner, resume)
    options = IdentifyOptions(load_space=preset.load_space, state_prior=preset.state_prior)
    settings = settings_for(resolve("mhe"), options)
    truth = preset.truth_mesh
    t0 = time.perf_counter()

    # One task list: the table's runs (with the oracle), the sign study's not already in the table,
    # and the consistency study's; shared truths and models are computed once for all of them.
    table_runs, sign_runs = preset.runs()
    table_tasks, shared = protocol_tasks(
        prob, table_runs, settings, truth, preset.oracle, jekf_modes=preset.jekf_modes, histories=True
    )
    sign_tasks, shared2 = protocol_tasks(prob, sign_runs, settings, truth, False, jekf_modes=preset.jekf_modes)
    cons_tasks, shared3 = consistency_tasks(prob, settings=settings, truth_nodes=truth)
    cache = out / _CONSISTENCY_FILE
    cons_rows = json.loads(cache.read_text()) if resume and cache.exists() and owner.owns(cache.name) else None
    if not preset.consistency or cons_rows is not None:
        cons_tasks = []
    table_keys = {t.key for t in table_tasks}
    tasks = table_tasks + [t for t in sign_tasks if t.key not in table_keys] + cons_tasks
    shared_all = {s.key: s for s in shared + shared2 + shared3}
    with Engine(engine) as running:
        if on_start is not None:
            on_start(running)
        by, _ = run_records(tasks, list(shared_all.values()), records, running, on_record, "compare")
    failed = [by[t.key] for t in tasks if by.get(t.key, {}).get("status") != "ok"]
    if failed:
        raise SolverError(
            f"{len(failed)} study tasks",
            f"failed, e.g. {failed[0]['key']}: {failed[0].get('error')}",
            "see records.jsonl",
        )

    report: dict = {"problem": prob.name, "truth_mesh": list(truth), "mesh": list(prob.nodes)}
    sections = _report(report, preset, prob, owner, by, table_tasks, sign_tasks, cons_tasks, cons_rows)
    report["wall_s"] = time.perf_counter() - t0
    sections.insert(0, checklist_markdown(report))
    text = "\n\n".join(s for s in sections if s) + "\n"
    owner.write_json("summary.json", report)
    owner.write_text("comparison.md", text)
    if doc:
        write_text_atomic(doc, doc_header(str(problem), preset) + text, what="doc", force=force, inputs=inputs)
    return report, text


_CONSISTENCY_FILE = "consistency.json"
"""The consistency study's rows, kept in the output directory (a resumed study does not rerun it)."""


def _check_size(prob: MembraneProblem, preset: ComparisonPreset) -> None:
    """Refuse, before any work, a comparison whose estimators would not fit (memory, time)."""
    from wingopt import resources

    samples = int(round(1.0 / prob.identification.dt)) + 1
    knobs = {"truth": f"--truth-mesh {preset.truth_mesh[0]}x{preset.truth_mesh[1]}"}
    for method in preset.methods or ("mhe",):
        need = resources.estimate_identify(
            prob.nodes, samples, truth_nodes=preset.truth_mesh, method=method, knobs=knobs, jekf_modes=preset.jekf_modes
        )
        resources.check(need)


def _record_log(owner: OwnedDirectory, resume: bool) -> RecordLog:
    """``records.jsonl`` of the study: kept on ``resume`` (a pre-engine file's records given their keys)."""
    rec_path = owner.path / "records.jsonl"
    if resume and rec_path.exists() and owner.owns("records.jsonl"):
        old = read_records(rec_path)
        if any("key" not in r for r in old):  # a pre-engine file: give its records their keys
            text = "".join(json.dumps(_keyed(r)) + "\n" for r in old)
            owner.write("records.jsonl", lambda tmp: tmp.write_text(text), log=True)
    return RecordLog(rec_path, fresh=not resume, owner=owner)


def _report(report, preset, prob, owner, by, table_tasks, sign_tasks, cons_tasks, cons_rows) -> list[str]:
    """The report's sections (table, oracle gap, sign and band, consistency, overlays) from the records
    ``by`` key, each also into ``report``; the consistency rows are cached in ``consistency.json``."""
    sections = []
    if preset.table:
        summ = summarize([record_from_dict(by[t.key]) for t in table_tasks])
        report["comparison"] = summ
        sections.append(comparison_markdown(summ, preset.title(prob)))
        sections.append(oracle_markdown(summ))
    if preset.sign_seeds:
        rows = summarize([record_from_dict(by[t.key]) for t in sign_tasks])
        report["sign_and_band"] = rows
        sections.append(sign_markdown(rows, preset.sign_seeds))
    if preset.consistency:
        if cons_rows is None:
            cons_rows = consistency_rows([by[t.key] for t in cons_tasks])
            owner.write_json(_CONSISTENCY_FILE, cons_rows)
        report["consistency"] = cons_rows
        sections.append(consistency_markdown(cons_rows))
    if preset.table:
        report["overlays"] = write_overlays(owner, [by[t.key] for t in table_tasks])
        if report["overlays"]:
            sections.append(
                "Lift histories of the MHE and the JEKFs with their 1-sigma bands and the true lift (lowest noise, "
                f"first seed), in the output directory: {', '.join(report['overlays'])}."
            )
    return sections


OVERLAY_NAMES = {"mhe": "MHE", "jekf-tuned": "tuned JEKF", "jekf-seed": "seed JEKF"}


def write_overlays(owner: OwnedDirectory, records: Sequence[dict]) -> list[str]:
    """``overlay-LOAD.png``: the lift histories of the MHE and the JEKFs, with their 1-sigma bands and
    the true lift, on the first table case (lowest noise, first seed) of every load that has the MHE
    and a JEKF. Returns the names written (records without histories, pre-overlay ones, are skipped)."""
    from wingopt.plots.identify import plot_overlay

    written = []
    by_case: dict[tuple, dict[str, dict]] = {}
    for rec in records:
        if rec.get("status", "ok") == "ok" and rec.get("history"):
            by_case.setdefault((rec["load"], rec["noise"], rec["seed"]), {})[rec["method"]] = rec
    for load in dict.fromkeys(k[0] for k in by_case):
        cases = sorted(k for k in by_case if k[0] == load and "mhe" in by_case[k] and len(by_case[k]) > 1)
        if not cases:
            continue
        _, noise, seed = cases[0]
        runs = by_case[cases[0]]
        curves = []
        for method, label in OVERLAY_NAMES.items():
            rec = runs.get(method)
            if rec is None:
                continue
            h = rec["history"]
            std = None if h.get("lift_std_N") is None else [float("nan") if v is None else v for v in h["lift_std_N"]]
            order = rec.get("params", {}).get("jekf_modes")
            curves.append((label + (f", {order} modes" if order else ""), h["t"], h["lift_N"], std))
        title = f"{load}, {100 * noise:g} % noise, seed {seed}"
        fig = plot_overlay(None, curves, None, runs["mhe"]["true_lift"], title)
        name = f"overlay-{load}.png"

        def fill(tmp: Path, fig=fig) -> None:
            fig.tight_layout()
            fig.savefig(tmp, format="png", dpi=110)

        owner.write(name, fill)
        written.append(name)
    return written
