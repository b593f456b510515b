"""``wingopt design-sensors``: where to put K stretch sensors on a membrane problem.

Writes into ``--out`` (atomically): ``summary.json`` (layout, predicted errors, relaxation bound and
gap, baselines, ``warnings``), ``sensors.toml`` (the ``[[sensors]]`` tables to paste) and
``layout.png`` (the layout over the predicted error field); ``--write-problem NEW.toml`` writes the
problem file with the designed sensors.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path

from wingopt.errors import InputError, OutputError

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
    p.add_argument("--noise", type=float, default=1.0, help="noise in PERCENT of each sensor's peak (default 1)")
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
    p.add_argument("--out", required=True, help="output directory (replaced atomically)")
    p.add_argument("--write-problem", metavar="NEW.toml", help="also write the problem file with the designed sensors")
    p.add_argument("--no-plots", action="store_true", help="skip the figure")
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    p.set_defaults(func=run)


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write a single file atomically (temporary sibling, then rename)."""
    target = Path(path).expanduser().resolve()
    if target.exists() and target.is_dir():
        raise OutputError(f"write-problem = {str(path)!r}: is a directory")
    if not target.parent.is_dir():
        raise OutputError(f"write-problem = {str(path)!r}: directory {str(target.parent)!r} does not exist")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.tmp-", dir=target.parent)
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, target)
    except OSError as exc:
        raise OutputError(f"write-problem = {str(path)!r}: cannot write it ({exc.strerror})") from None
    return target


def run(args) -> int:
    from wingopt.design import DesignSettings, InformationSettings, design_sensors
    from wingopt.design.figure import layout_figure
    from wingopt.design.toml_text import problem_text, read_problem_table, sensors_text
    from wingopt.problem import _resolve as resolve_problem
    from wingopt.problem import load_problem
    from wingopt.results import ResultDirectory, to_jsonable, write_json
    from wingopt.results.writer import check_writable

    check_writable(args.out)
    if not (0 < args.noise <= 100):
        raise InputError(f"noise = {args.noise!r}: expected a percentage in (0, 100]")
    problem = load_problem(args.problem)
    if problem.kind != "membrane":
        raise InputError(f"problem = {args.problem!r}: design-sensors needs a membrane problem, got {problem.kind!r}")
    settings = DesignSettings(
        criterion=args.criterion,
        prior=args.prior,
        length_scale=args.length_scale,
        nominal_count=args.nominal,
        aggregate=args.aggregate,
        allow_overlap=args.allow_overlap,
        information=InformationSettings(
            noise=args.noise / 100.0, t_end=args.t_end, window_s=min(0.2, args.t_end) if args.t_end > 0 else 0.2
        ),
    )
    if args.montecarlo < 0 or (args.montecarlo and args.criterion != "risk"):
        raise InputError(f"montecarlo = {args.montecarlo}: expected a positive short-list size, with --criterion risk")
    result = design_sensors(problem, args.count, args.candidates, settings)
    if args.montecarlo:
        from wingopt.design.rerank import MonteCarloSettings, adopt, rerank

        mcs = MonteCarloSettings(shortlist=args.montecarlo, noise=args.noise / 100.0, t_end=args.t_end)
        result = adopt(result, rerank(result, mcs))
    summary = result.summary()
    header = (
        f"{result.count} sensors designed by wingopt design-sensors ({args.criterion}) for {problem.name};\n"
        f"predicted mean relative load error {result.predictions['risk_relative_load_error']:.3f}"
    )
    toml = sensors_text(result.rects, header=header)
    with ResultDirectory(args.out) as tmp:
        write_json(tmp / "summary.json", to_jsonable(summary))
        (tmp / "sensors.toml").write_text(toml)
        if not args.no_plots:
            fig = layout_figure(result, [s.rect for s in problem.sensors])
            fig.savefig(tmp / "layout.png", dpi=120)
    if args.write_problem:
        table = read_problem_table(resolve_problem(args.problem))
        write_text_atomic(args.write_problem, problem_text(table, result.rects, header=header))
    if args.json:
        print(json.dumps(to_jsonable(summary), indent=2))
    else:
        print(toml, end="")
        rel = result.relaxation
        print(
            f"# criterion {args.criterion}: {result.value:.4g}; A-relaxation bound {rel['bound']:.4g}, "
            f"chosen {rel['chosen_reduced']:.4g} (gap {rel['gap']:.3g})"
        )
        for w in result.warnings:
            print(f"# warning: {w}")
    return 0
