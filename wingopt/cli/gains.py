"""``wingopt gains``: full-order continuous LQR gains on several meshes and their functional gains.

Parses the options and calls :func:`wingopt.workflows.gains.gains_to_directory` (the seed's
eq. 5.29, Figs. 5.12–5.17: NK-ADI gains mapped back to fields).
"""

from __future__ import annotations

import json

from wingopt.cli import OUT_HELP
from wingopt.cli.helptext import Formatter
from wingopt.problem import parse_mesh
from wingopt.results import to_jsonable
from wingopt.workflows.gains import gains_to_directory

ORDER = 25

EXAMPLE = """examples:
  wingopt gains plate --out runs/gains                                  # 7x31, 13x61, 25x121
  wingopt gains plate --meshes 7x31,13x61 --out runs/gains-small --json
  wingopt gains plate --cache runs/gain-cache --out runs/gains          # reuse computed gains

The 25x121 gain takes minutes on a 2-core machine (see docs/control_lqr.md); --cache keeps each
mesh's gain (gains_<mesh>.npz) so that plots can be redrawn without recomputing it."""


def register(sub, common) -> None:
    p = sub.add_parser(
        "gains",
        parents=[common],
        help="full-order LQR gains on several meshes and the convergence of their functional gains",
        description="Compute the continuous full-order LQR gain of the plate on each mesh (Newton-Kleinman with "
        "low-rank ADI) and plot the functional gains of eq. 5.29 for PZ1, PZ4 and PZ7 along x = W/2.",
        epilog=EXAMPLE,
        formatter_class=Formatter,
    )
    p.add_argument("problem", help="problem file (.toml) or built-in name (plate)")
    p.add_argument("--meshes", default="7x31,13x61,25x121", help="comma-separated meshes (default the seed's three)")
    p.add_argument("--r", type=float, help="input weight R = r I, V^-2 (default 1e-10)")
    p.add_argument("--weight-modes", type=int, help="modes in the state weight (default 20)")
    p.add_argument("--cache", help="directory to keep/reuse gains_<mesh>.npz")
    p.add_argument("--out", required=True, metavar="DIR", help=OUT_HELP)
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    p.set_defaults(func=run)


def run(args) -> int:
    meshes = [parse_mesh(t) for t in args.meshes.split(",") if t.strip()]
    summary = gains_to_directory(args.problem, meshes, args.out, args.r, args.weight_modes, args.cache)
    if args.json:
        print(json.dumps(to_jsonable(summary)))
    else:
        for rec in summary["meshes"]:
            how = "cached" if rec.get("cached") else f"{rec.get('total_s', 0):.1f} s"
            print(f"{rec['mesh']:>7}: {rec['states']} states, {rec.get('newton_steps')} Newton steps, {how}")
        print(f"-> {args.out}")
    return 0
