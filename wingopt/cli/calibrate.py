"""``wingopt calibrate``: the membrane's prestrains and damping from a record without load.

A release, a pluck or a tap recorded before the run (no flow) rings at the membrane's modal
frequencies; the fit gives the prestrains and the damping with their posterior, written into
``summary.json`` and, with ``--write-problem``, into a copy of the problem file whose
``[identification]`` then carries them: ``wingopt identify`` with that file takes them as its prior.
"""

from __future__ import annotations

import dataclasses
import json

from wingopt.cli import OUT_HELP, add_force_option
from wingopt.cli import options as opt
from wingopt.cli.helptext import Formatter
from wingopt.problem import load_problem, parse_mesh
from wingopt.resources import parse_size
from wingopt.results import check_new_file, check_writable, to_jsonable
from wingopt.workflows.calibrate import calibrate_membrane, calibration_inputs, write_calibration_outputs

ORDER = 35

EXAMPLE = """examples:
  wingopt calibrate membrane --data pluck.csv --out runs/cal --write-problem calibrated.toml
  wingopt identify calibrated.toml --data tunnel.csv --out runs/tunnel    # the calibration is the prior
  wingopt calibrate membrane --data release.csv --release-peak 0.004 --out runs/cal   # released from a 4 mm bubble
  (the record: header 't,S1,S2,S3,S4', no load on the wing)"""


def register(sub, common) -> None:
    p = sub.add_parser(
        "calibrate",
        parents=[common],
        help="identify the membrane's prestrains and damping from a record without load",
        description="Fit the membrane (FvK) to a calibration record taken with no load (a release, a pluck or a "
        "tap): the prestrains and the damping factor with their posterior; with --write-problem, a problem file "
        "that carries them as the prior of later identifications.",
        epilog=EXAMPLE,
        formatter_class=Formatter,
    )
    p.add_argument("problem", help="problem file (.toml) or built-in name (membrane)")
    p.add_argument(
        "--data", required=True, metavar="FILE.csv", help="the calibration record (t + one column per sensor)"
    )
    p.add_argument(
        "--release-peak",
        type=float,
        metavar="M",
        help="the record starts at rest in the protocol's bubble shape with this peak (m); default: the initial "
        "shape is unknown (a pluck or a tap) and identified",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="summary.json; " + OUT_HELP)
    p.add_argument(
        "--write-problem",
        metavar="NEW.toml",
        help="write the problem file with the calibration as [identification] prior (an existing file, the input "
        "problem file included, is refused unless --force)",
    )
    add_force_option(p, "--write-problem", "NEW.toml")
    opt.add(p, "--mesh", help="estimator mesh (default: the problem's)")
    opt.add(p, "--noise-std")
    p.add_argument("--max-memory", metavar="SIZE", help="refuse runs estimated to need more (e.g. 4G)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    opt.add_channel_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    inputs = calibration_inputs(args.problem, args.data)
    check_writable(args.out, inputs=[*inputs, ("--write-problem", args.write_problem)])
    if args.write_problem is not None:
        check_new_file(args.write_problem, "--write-problem", force=args.force, inputs=inputs)
    problem = args.problem
    if opt.channel_options_given(args):  # a DAQ's columns, gains, offsets over the problem's [measurements]
        problem = load_problem(args.problem)
        problem = dataclasses.replace(problem, measurements=opt.channel_map(args, problem))
    run_ = calibrate_membrane(
        problem,
        args.data,
        nodes=parse_mesh(args.mesh) if args.mesh else None,
        release_peak=args.release_peak,
        noise_std=args.noise_std,
        max_memory=parse_size(args.max_memory) if args.max_memory else None,
    )
    _, written, backup = write_calibration_outputs(run_, args.out, args.write_problem, force=args.force)
    summary = to_jsonable(run_.summary())
    if args.json:
        print(json.dumps(summary))
        return 0
    p, s = summary["parameters"], summary["parameters_std"]
    r = summary["correlation"]["matrix"][0][1]
    print(
        f"calibrate: prestrain ({p['prestrain_x']:.5f} ± {s['prestrain_x']:.2g}, {p['prestrain_y']:.5f} ± "
        f"{s['prestrain_y']:.2g}), correlation {r:+.2f}, damping x{p['damping']:.3f} ± {s['damping']:.2g}, "
        f"chi-square per datum {summary['chi2_per_datum']:.2f} -> {args.out}"
        + (f"; problem file {written}" if written else "")
        + (f" (the earlier one kept as {backup})" if backup else "")
    )
    return 0
