"""``wingopt design-sensors``: where to put K stretch sensors on a membrane problem.

Writes into ``--out`` (atomically): ``summary.json`` (layout, predicted errors, relaxation bound and
gap, baselines, ``warnings``), ``sensors.toml`` (the ``[[sensors]]`` tables to paste) and
``layout.png`` (the layout over the predicted error field); ``--write-problem NEW.toml`` writes the
problem file with the designed sensors (an existing file is refused unless ``--force``, and then kept
as ``NEW.toml.bak``). It parses and calls :func:`wingopt.workflows.design.run_design`.
"""

from __future__ import annotations

import argparse
import json

from wingopt.cli import OUT_HELP, add_force_option
from wingopt.cli import options as opt
from wingopt.errors import InputError

ORDER = 35

EXAMPLE = """examples:
  wingopt design-sensors membrane --count 4 --out runs/design4
  wingopt design-sensors membrane --count 6 --criterion a --prior gp --out runs/design6a
  wingopt design-sensors membrane --count 4 --candidates "sizes=0.035x0.012,0.012x0.035;step=2" --out runs/d4
  wingopt design-sensors membrane --count 4 --candidates "keepout=0.06:0.08:0:0.07" \\
      --write-problem membrane_designed.toml --out runs/d4k

criteria: risk (default; the estimator's expected error: Tikhonov bias + noise, its own lambda rule),
a (A-optimal: expected L2 load error under the prior), lift (lift variance), d (D-optimal).
--candidates SPEC: ';'-separated sizes=WxH[,WxH], step=N (lattice cells), keepout=x0:x1:y0:y1,
rect=x0:x1:y0:y1, only-rects (metres). Default: the problem's sensor sizes on the half-element lattice."""


def register(sub, common) -> None:
    p = sub.add_parser(
        "design-sensors",
        parents=[common],
        help="optimal stretch-sensor layout for membrane load identification",
        description="Choose K sensor rectangles that minimise the predicted identification error: "
        "candidates x linearised information x a Bayesian criterion, convex relaxation (bound), rounding, swaps.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("problem", help="membrane problem file (.toml) or built-in name (membrane)")
    p.add_argument("--count", type=int, required=True, help="number of sensors K")
    p.add_argument("--candidates", metavar="SPEC", help="candidate set (see below)")
    p.add_argument("--criterion", choices=("risk", "a", "lift", "d"), default="risk", help="design criterion")
    p.add_argument("--prior", choices=("gp", "tikhonov"), default="gp", help="load prior of a/lift/d (default gp)")
    p.add_argument("--length-scale", type=float, help="GP length scale, m (default 0.3 of the chord)")
    p.add_argument(
        "--nominal", type=int, help="nominal loads the design is robust over (default 12 for risk, 4 for a/lift/d)"
    )
    p.add_argument("--aggregate", choices=("mean", "max"), default="mean", help="over the nominal loads")
    p.add_argument(
        "--noise",
        "--noise-percent",
        dest="noise",
        type=opt.percent,
        default=1.0,
        help="noise in PERCENT of each sensor's peak (default 1; Python: noise_fraction = this / 100)",
    )
    p.add_argument("--t-end", type=float, default=1.0, help="record length, s (default 1)")
    p.add_argument(
        "--montecarlo",
        type=int,
        default=0,
        metavar="N",
        help="re-rank the design's N best layouts by the estimator's mean error on the nominal loads (risk only; "
        "about 8 N identifications)",
    )
    p.add_argument("--allow-overlap", action="store_true", help="let chosen rectangles overlap")
    p.add_argument("--out", required=True, help=OUT_HELP)
    p.add_argument(
        "--write-problem",
        metavar="NEW.toml",
        help="also write the problem file with the designed sensors (atomically; an existing file, the input "
        "problem file included, is refused unless --force)",
    )
    add_force_option(p, "--write-problem", "NEW.toml")
    p.add_argument("--no-plots", action="store_true", help="skip the figure")
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    p.set_defaults(func=run)


def run(args) -> int:
    from wingopt.results import to_jsonable
    from wingopt.workflows.design import run_design

    if not (0 < args.noise <= 100):
        raise InputError(f"noise = {args.noise!r}: expected a percentage in (0, 100]")
    done = run_design(
        args.problem,
        args.count,
        args.out,
        candidates=args.candidates,
        montecarlo=args.montecarlo,
        plots=not args.no_plots,
        write_problem=args.write_problem,
        force=args.force,
        criterion=args.criterion,
        prior=args.prior,
        length_scale=args.length_scale,
        nominal_count=args.nominal,
        aggregate=args.aggregate,
        noise_fraction=args.noise / 100.0,
        t_end=args.t_end,
        allow_overlap=args.allow_overlap,
    )
    result = done.result
    if args.json:
        print(json.dumps(to_jsonable(done.summary), indent=2))
    else:
        print(done.sensors_toml, end="")
        rel = result.relaxation
        print(
            f"# criterion {args.criterion}: {result.value:.4g}; A-relaxation bound {rel['bound']:.4g}, "
            f"chosen {rel['chosen_reduced']:.4g} (gap {rel['gap']:.3g})"
        )
        for w in result.warnings:
            print(f"# warning: {w}")
        if done.backup is not None:
            print(f"# kept the earlier {args.write_problem} as {done.backup}")
    return 0
