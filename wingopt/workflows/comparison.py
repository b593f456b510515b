"""The estimator studies as sweeps on the study engine: the comparison table, sign and band, consistency.

Each study is a list of independent tasks (:mod:`wingopt.workflows.sweep.protocol`) run by the
engine (serial, a local cluster, or a scheduler); the per-case pieces (simulated cases, running a
method, scoring it) are in :mod:`wingopt.workflows.studies`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence

from wingopt.estimation.mhe import MHESettings
from wingopt.problem.membrane import MembraneProblem
from wingopt.workflows.protocols import TRUTH_NODES
from wingopt.workflows.studies import METHODS, ORACLE_OFFSETS, CaseRecord, record_from_dict

__all__ = ["comparison_study", "sign_and_band_study", "consistency_study"]


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
    from wingopt.workflows.sweep.protocol import protocol_tasks, run_tasks, task_key

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
    from wingopt.workflows.sweep.protocol import consistency_rows, consistency_tasks, run_tasks

    tasks, shared = consistency_tasks(problem, layouts, noise, seeds, mhe_settings, truth_nodes)
    records = run_tasks(tasks, shared, jobs, engine)
    order = {t.key: i for i, t in enumerate(tasks)}
    rows = consistency_rows(sorted(records, key=lambda r: order[r["key"]]))
    for row in rows:
        if progress:
            progress(f"consistency, {row['sensors']} sensors: load error {row['load_error_mean']:.4f}")
    return rows
