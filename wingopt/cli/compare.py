"""``wingopt compare``: the estimator comparison, sign/band and consistency studies (issue 5).

Runs the simulated protocol (truth on 49x25, estimator on the problem's mesh) for L1–L3 x noise
levels x noise seeds with the MHE, the seed-faithful JEKF and the tuned JEKF, prints the table
(mean and min–max over seeds) next to the seed's numbers and writes it, with every record, to
``--out``. It is a preset sweep on the study engine (:func:`wingopt.workflows.comparison.run_comparison`):
``--workers N`` runs N worker processes of a local dask cluster (1: in this process), ``--scheduler``
attaches to a running one. Records are appended to ``DIR/records.jsonl`` as they finish, so an
interrupted study resumes where it stopped (``--resume``; nothing recorded is recomputed) and
methods can be run separately and merged. Without ``--resume`` the records file is started afresh.
The JEKFs keep their lowest 60 modes unless ``--jekf-order full`` (the exact filter, ~20x the CPU
time); the tasks run cheapest first, a stage line on stderr as each finishes, and
``DIR/overlay-LOAD.png`` puts the MHE's and the JEKFs' lift histories side by side.
"""

from __future__ import annotations

import json

from wingopt.cli import OUT_HELP, add_force_option
from wingopt.cli import options as opt
from wingopt.cli.helptext import Formatter, add_help_all, advanced
from wingopt.cli.identify import parse_noise
from wingopt.cli.sweep import add_engine_options, announce, engine_settings
from wingopt.errors import InputError
from wingopt.problem import parse_mesh
from wingopt.results import to_jsonable
from wingopt.workflows.comparison import JEKF_MODES, ComparisonPreset, run_comparison

ORDER = 40

EXAMPLE = """examples (more in docs/cli.md):
  wingopt compare membrane --out runs/compare --workers 2
  wingopt compare membrane --methods mhe --n-seeds 5 --out runs/cmp --resume"""


def register(sub, common) -> None:
    p = sub.add_parser(
        "compare",
        parents=[common],
        help="compare the MHE with the seed's and a tuned JEKF on the simulated protocol",
        usage="%(prog)s PROBLEM --out DIR [options]",
        description="Estimators on L1-L3 x noise x seeds (MHE, seed JEKF, tuned JEKF), the MHE's\n"
        "sign and lift-band checks over many seeds, and the sensor-count consistency study.",
        epilog=EXAMPLE,
        formatter_class=Formatter,
    )
    add_help_all(p)
    p.add_argument("problem", help="membrane problem file or built-in name")
    p.add_argument("--loads", default="L1,L2,L3", metavar="LIST", help="load cases (default L1,L2,L3)")
    p.add_argument("--noise", default="1,5", metavar="PERCENT", help="noise levels, %% of each peak (1,5)")
    opt.add(p, "--n-seeds", dest="seeds", default=5, help="noise seeds 0..N-1 (default 5)", aliases=("--seeds",))
    advanced(
        p.add_argument(
            "--first-seed",
            type=int,
            default=0,
            metavar="N",
            help="table seeds FIRST..FIRST+N-1 instead (e.g. 200: out-of-sample check of the lambda rule)",
        )
    )
    p.add_argument("--methods", default="mhe,jekf-seed,jekf-tuned", metavar="LIST", help="methods (all three)")
    p.add_argument("--table", choices=("yes", "no"), default="yes", metavar="yes|no", help="the table (yes)")
    p.add_argument("--no-oracle", action="store_true", help="skip the MHE's oracle-lambda runs")
    opt.add(
        p,
        "--n-sign-seeds",
        dest="sign_seeds",
        type=int,
        metavar="N",
        default=0,
        help="MHE sign/band check over N seeds (5 %% noise)",
        aliases=("--sign-seeds",),
    )
    p.add_argument("--consistency", action="store_true", help="run the sensor-count consistency study")
    advanced(p.add_argument("--load-space", choices=("fixed", "free"), default="fixed", help="MHE load space"))
    advanced(
        p.add_argument(
            "--state-prior", default="1", metavar="S|evidence", help="MHE initial-state prior (default 1) or 'evidence'"
        )
    )
    opt.add(p, "--truth-mesh")
    p.add_argument(
        "--jekf-order",
        default=str(JEKF_MODES),
        metavar="N|full",
        help=f"JEKF modes kept (default {JEKF_MODES}) or 'full' (exact)",
    )
    opt.add(
        p,
        "--workers",
        dest="jobs",
        default=1,
        help="local dask workers (default 1: in this process)",
        aliases=("--jobs",),
    )
    p.add_argument("--resume", action="store_true", help="keep the records already in DIR/records.jsonl")
    p.add_argument("--out", required=True, metavar="DIR", help=OUT_HELP)
    p.add_argument("--doc", metavar="FILE", help="also write the markdown report to FILE")
    add_force_option(p, "--doc", "FILE")
    p.add_argument("--json", action="store_true", help="print the summary as JSON instead of the table")
    add_engine_options(p, workers_flag=None)
    p.set_defaults(func=run)


def parse_order(text: str) -> int | None:
    """``--jekf-order``: ``"full"`` -> ``None`` (every mode), ``"60"`` -> 60."""
    word = str(text).strip().lower()
    if word in ("full", "all", "exact"):
        return None
    try:
        value = int(word)
    except ValueError:
        value = 0
    if value < 1:
        raise InputError(f"jekf-order = {text!r}: expected a positive number of modes (e.g. 60) or 'full'")
    return value


def _items(text: str) -> tuple[str, ...]:
    return tuple(s.strip() for s in text.split(",") if s.strip())


def _show(rec: dict) -> None:
    """One line per finished task (a failure, or a run of the table or the sign study)."""
    if rec.get("status") != "ok":
        print(f"  FAILED {rec['key']}: {rec.get('error')}", flush=True)
    elif "study" not in rec.get("params", {}):
        print(
            f"  {rec['load']} {100 * rec['noise']:g}% seed {rec['seed']} {rec['method']}: load "
            f"{rec['load_error']:.4f} deflection {rec['deflection_error']:.2e} lift {rec['lift_error']:.4f} "
            f"({rec['wall_s']:.1f} s)",
            flush=True,
        )


def run(args) -> int:
    preset = ComparisonPreset(
        loads=_items(args.loads),
        noise_fractions=tuple(parse_noise(s) for s in _items(args.noise)),
        seeds=args.seeds,
        first_seed=args.first_seed,
        methods=_items(args.methods),
        table=args.table == "yes",
        oracle=not args.no_oracle,
        sign_seeds=args.sign_seeds,
        consistency=args.consistency,
        load_space=args.load_space,
        state_prior=args.state_prior,
        truth_mesh=parse_mesh(args.truth_mesh),
        jekf_modes=parse_order(args.jekf_order),
    )
    if args.jobs < 1:
        raise InputError(f"workers = {args.jobs}: expected a positive integer")
    args.serial = args.serial or (args.jobs <= 1 and not args.scheduler)

    def start(engine) -> None:
        if engine.client is not None or args.jobs > 1:
            announce(engine)

    report, text = run_comparison(
        args.problem,
        args.out,
        preset,
        engine_settings(args, args.jobs, retries=2),
        resume=args.resume,
        doc=args.doc,
        force=args.force,
        on_start=start,
        on_record=_show,
    )
    for row in report.get("consistency", []):
        print(f"consistency, {row['sensors']} sensors: load error {row['load_error_mean']:.4f}")
    if args.json:
        print(json.dumps(to_jsonable(report)))
    else:
        print(text)
    return 0
