"""``wingopt demo``: the main job on the built-in problems, results in ``./wingopt-demo/``."""

from __future__ import annotations

import json

from wingopt.cli import OUT_HELP
from wingopt.cli import options as opt
from wingopt.cli.helptext import Formatter
from wingopt.results import to_jsonable

ORDER = 1

EXAMPLE = """examples:
  wingopt demo                       # writes ./wingopt-demo/report.html (about 1.6 CPU-minutes)
  wingopt demo --out /tmp/demo --quick --json      # about 40 s of CPU
each of the 21 runs is a line on stderr with the time so far and an estimate of the rest (-q: none)"""


def register(sub, common) -> None:
    p = sub.add_parser(
        "demo",
        parents=[common],
        help="morph the plate (QP vs LQR) and identify membrane loads (MHE vs JEKF); write a report",
        description="Run the main job on the built-in problems: plate morphing into twist, camber and bending "
        "with the QP controller and the seed's LQR, and load identification L1-L3 with the MHE and the JEKF. "
        "Writes per-run outputs, summary.json and a self-contained report.html.",
        epilog=EXAMPLE,
        formatter_class=Formatter,
    )
    p.add_argument("--out", default="wingopt-demo", metavar="DIR", help="default ./wingopt-demo; " + OUT_HELP)
    p.add_argument("--quick", action="store_true", help="coarse meshes and short runs (a smoke test, not the results)")
    opt.add(p, "--force")
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    p.set_defaults(func=run)


def run(args) -> int:
    from wingopt import resources
    from wingopt.workflows.demo import DemoConfig, run_demo
    from wingopt.workflows.demo_report import summary_table

    with resources.long_runs(args.force, "--force"):
        summary = run_demo(
            args.out, DemoConfig.quick() if args.quick else DemoConfig(), progress=None if not args.quiet else False
        )
    if args.json:
        print(json.dumps(to_jsonable(summary)))
    else:
        print(summary_table(summary))
        print(f"report: {args.out}/report.html")
    return 0
