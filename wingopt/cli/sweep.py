"""``wingopt sweep``: a study over any problem field, load, noise, seed, method or estimator setting.

Runs every case of a TOML sweep spec (docs/studies.md) on the study engine: an embedded dask
``LocalCluster`` (one process per core) by default, an existing scheduler (``--scheduler``) or a
batch cluster (``--cluster slurm|pbs``, from the spec's ``[cluster]`` table). Records are appended
to ``DIR/records.jsonl`` as tasks finish; ``--resume`` runs only what is not recorded yet.
"""

from __future__ import annotations

import argparse
import json

from wingopt.cli import OUT_HELP
from wingopt.cli.helptext import Formatter
from wingopt.cli.options import add
from wingopt.errors import InputError

ORDER = 45

EXAMPLE = """examples:
  wingopt sweep study.toml --out runs/study                   # all cores of this machine
  wingopt sweep study.toml --out runs/study --resume          # continue an interrupted sweep
  wingopt sweep study.toml --out runs/study --scheduler tcp://head:8786
  wingopt sweep study.toml --out runs/study --cluster slurm   # needs pip install 'wingopt[cluster]'"""


def add_engine_options(p: argparse.ArgumentParser, workers_flag: str = "--workers") -> None:
    """The engine's options (shared by ``sweep`` and ``compare``)."""
    g = p.add_argument_group("where the tasks run")
    x = g.add_mutually_exclusive_group()
    x.add_argument("--scheduler", metavar="ADDRESS", help="attach to a running dask scheduler (tcp://host:8786)")
    x.add_argument("--serial", action="store_true", help="run every task in this process (no dask; debugging)")
    if workers_flag == "--workers":
        x.add_argument("--cluster", choices=("slurm", "pbs"), help="start a dask-jobqueue cluster (spec [cluster])")
        add(g, "--workers", help="local worker processes (default: CPU count) or batch jobs (--cluster)")
    g.add_argument("--retries", type=int, help="re-runs of a task whose worker died or that failed (default 2)")


def engine_settings(args, workers: int | None, cluster: dict | None = None, retries: int = 2):
    """:class:`EngineSettings` from the parsed options."""
    from wingopt.workflows.sweep.engine import EngineSettings

    if getattr(args, "scheduler", None):
        mode = "scheduler"
    elif getattr(args, "serial", False):
        mode = "serial"
    elif getattr(args, "cluster", None):
        mode = args.cluster
    else:
        mode = "local"
    retries = args.retries if getattr(args, "retries", None) is not None else retries
    return EngineSettings(
        mode=mode,
        workers=workers,
        scheduler=getattr(args, "scheduler", None),
        cluster=dict(cluster or {}),
        retries=retries,
        progress=True,  # stage lines on stderr (wingopt.progress), terminal or not
    )


def announce(engine) -> None:
    """Say where the tasks run and where the dashboard is."""
    if engine.client is None:
        print("engine: serial (this process)", flush=True)
        return
    link = engine.dashboard_link
    where = f"dashboard {link}" if link else "no dashboard (pip install bokeh for one)"
    print(f"engine: {engine.settings.mode}, {engine.n_workers} workers, {where}", flush=True)


def register(sub, common) -> None:
    p = sub.add_parser(
        "sweep",
        parents=[common],
        help="run a study over problem fields, loads, noise, seeds and methods (dask; resumable)",
        description="Run every case of a sweep spec (TOML; docs/studies.md) on a local dask cluster, an existing "
        "scheduler or a batch cluster. One JSON record per task in DIR/records.jsonl, the per-case table in "
        "DIR/table.csv (and .parquet with pyarrow), DIR/summary.json.",
        epilog=EXAMPLE,
        formatter_class=Formatter,
    )
    p.add_argument("spec", help="sweep spec (TOML)")
    p.add_argument("--out", required=True, metavar="DIR", help=OUT_HELP)
    p.add_argument("--resume", action="store_true", help="keep DIR/records.jsonl and run only what is missing")
    add_engine_options(p)
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def run(args) -> int:
    from wingopt.workflows.sweep.engine import Engine
    from wingopt.workflows.sweep.run import run_sweep
    from wingopt.workflows.sweep.spec import load_spec

    if args.workers is not None and args.workers < 1:
        raise InputError(f"workers = {args.workers}: expected a positive integer")
    from wingopt.results import check_writable
    from wingopt.workflows.sweep.run import spec_inputs

    spec = load_spec(args.spec)
    check_writable(args.out, inputs=spec_inputs(spec))  # before the engine starts
    settings = engine_settings(args, args.workers, spec.cluster, spec.retries)

    def show(rec):
        if rec.get("status") != "ok":
            print(f"  FAILED {rec['key']}: {rec.get('error')}", flush=True)

    with Engine(settings) as engine:
        announce(engine)
        summary = run_sweep(spec, args.out, engine, resume=args.resume, on_record=show)
    if args.json:
        print(json.dumps(summary, default=str))
    else:
        print(
            f"{summary['recorded']} of {summary['tasks']} tasks recorded ({summary['ran']} run now, "
            f"{len(summary['failed'])} failed) in {summary['wall_s']:.1f} s; table: "
            f"{', '.join(summary['tables'])} in {args.out}"
        )
    return 0 if not summary["failed"] else 3
