"""``wingopt design-sensors``: where to put K stretch sensors on a membrane problem.

Writes into ``--out`` (atomically): ``summary.json`` (layout, predicted errors, relaxation bound and
gap, baselines, ``warnings``), ``sensors.toml`` (the ``[[sensors]]`` tables to paste) and
``layout.png`` (the layout over the predicted error field); ``--write-problem NEW.toml`` writes the
problem file with the designed sensors (an existing file is refused unless ``--force``, and then kept
as ``NEW.toml.bak``). It parses and calls :func:`wingopt.workflows.design.run_design`.
"""

from __future__ import annotations

import json

from wingopt.cli import OUT_HELP, add_force_option
from wingopt.cli import options as opt
from wingopt.cli.helptext import Formatter, add_help_all, advanced
from wingopt.errors import InputError

ORDER = 35

EXAMPLE = """criteria: risk (the estimator's expected error), a (A-optimal), lift, d (D-opt.).
--candidates SPEC: ';'-separated sizes=WxH[,WxH], step=N, keepout=x0:x1:y0:y1,
rect=x0:x1:y0:y1, only-rects (metres); docs/cli.md and docs/sensor_design.md.

examples:
  wingopt design-sensors membrane --count 4 --out runs/design4
  wingopt design-sensors membrane --count 4 --candidates "step=2" --out runs/d4"""


def register(sub, common) -> None:
    p = sub.add_parser(
        "design-sensors",
        parents=[common],
        help="optimal stretch-sensor layout for membrane load identification",
        usage="%(prog)s PROBLEM --count N --out DIR [options]",
        description="Choose N sensor rectangles that minimise the predicted identification error\n"
        "(candidates, linearised information, convex relaxation with a bound, swaps).",
        epilog=EXAMPLE,
        formatter_class=Formatter,
    )
    add_help_all(p)
    p.add_argument("problem", help="membrane problem file (.toml) or built-in name")
    p.add_argument("--count", type=int, required=True, metavar="N", help="number of sensors")
    p.add_argument("--candidates", metavar="SPEC", help="candidate set (below; default: the problem's sizes)")
    p.add_argument(
        "--criterion", choices=("risk", "a", "lift", "d"), default="risk", metavar="NAME", help="risk, a, lift, d"
    )
    p.add_argument(
        "--prior", choices=("gp", "tikhonov"), default="gp", metavar="NAME", help="a/lift/d load prior: gp, tikhonov"
    )
    p.add_argument("--length-scale", type=float, metavar="M", help="GP length scale, m (default 0.2 of the chord)")
    p.add_argument("--nominal", type=int, metavar="N", help="nominal loads (default 12 risk, 4 a/lift/d)")
    p.add_argument(
        "--aggregate", choices=("mean", "max"), default="mean", metavar="HOW", help="over the loads: mean, max"
    )
    p.add_argument("--noise", type=opt.percent, default=1.0, metavar="PERCENT", help="noise, %% of each peak (1)")
    advanced(p.add_argument("--noise-percent", dest="noise", type=opt.percent, metavar="PERCENT", help="as --noise"))
    opt.add(p, "--t-end", default=1.0, help="record length, s (default 1)")
    p.add_argument(
        "--montecarlo", type=int, default=0, metavar="N", help="re-rank the N best layouts by the estimator (risk)"
    )
    p.add_argument("--allow-overlap", action="store_true", help="let chosen rectangles overlap")
    p.add_argument("--out", required=True, metavar="DIR", help=OUT_HELP)
    p.add_argument("--write-problem", metavar="NEW.toml", help="also write the problem file with the design")
    add_force_option(p, "--write-problem", "NEW.toml")
    p.add_argument("--no-plots", action="store_true", help="skip the figure")
    opt.add(p, "--json")
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
