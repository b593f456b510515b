"""``wingopt morph``: morph the plate into a Table 5.1 shape (LQR/LQG baseline or QP/MPC).

Writes ``summary.json``, ``voltages.csv``, ``history.csv`` and figures into ``--out`` atomically
(a failed run leaves no half-written directory). With ``--method qp`` the LQR saturated at the
same limits runs too and the figures compare the two.
"""

from __future__ import annotations

import json
import math

from wingopt import resources
from wingopt.cli import OUT_HELP
from wingopt.cli import options as opt
from wingopt.cli.helptext import Formatter, add_help_all, advanced
from wingopt.errors import InputError
from wingopt.optim.registry import BACKENDS, FALLBACK
from wingopt.plate.shapes import SHAPES
from wingopt.problem import parse_mesh
from wingopt.results import to_jsonable
from wingopt.validate import check_seed
from wingopt.workflows.morph import METHODS, morph_to_directory
from wingopt.workflows.morph_plant import HysteresisSettings, parse_plant_scale

PLANT_KINDS = ("auto", "dense", "modal")

ORDER = 20

USAGE = "%(prog)s PROBLEM --shape SHAPE --out DIR [options]"

EXAMPLE = """voltage limits: qp keeps the problem's [actuators] (-500/+1500 V) and runs the LQR saturated there
  too; lqr saturates at --vmin/--vmax when given (the seed's law: unlimited otherwise).
examples (more, and a plant that is not the model, in docs/cli.md and docs/control_qp.md):
  wingopt morph plate --shape twist --method lqr --out runs/twist-lqr
  wingopt morph plate --shape camber --plant-scale moduli=1.1,d33=0.8 --hysteresis 0.15 --out runs/c"""


def register(sub, common) -> None:
    p = sub.add_parser(
        "morph",
        parents=[common],
        help="morph the plate wing into twist, camber or bending (QP or LQR/LQG)",
        usage=USAGE,
        description="Closed-loop morphing of the piezo-actuated plate wing into a Table 5.1 shape.",
        epilog=EXAMPLE,
        formatter_class=Formatter,
    )
    add_help_all(p)
    p.add_argument("problem", help="problem file (.toml) or built-in name (plate)")
    p.add_argument("--shape", required=True, metavar="SHAPE", help="twist, camber or bending")
    opt.add(p, "--method", default="qp", help="controller: qp (default) or lqr")
    p.add_argument("--vmin", type=float, metavar="V", help="lowest patch voltage, V")
    p.add_argument("--vmax", type=float, metavar="V", help="highest patch voltage, V")
    opt.add(p, "--t-end", default=2.0, help="duration, s (default 2)")
    opt.add(p, "--mesh", help="nodes in x and y, e.g. 13x61 (default: the problem's)")
    advanced(p.add_argument("--period", type=float, default=0.01, metavar="S", help="control period, s (0.01)"))
    advanced(p.add_argument("--sensor-noise", type=float, default=0.0, metavar="STD", help="sensor noise std, m"))
    advanced(opt.add(p, "--seed"))
    m = p.add_argument_group("a plant that is not the model (docs/control_qp.md)")
    m.add_argument(
        "--plant",
        default="auto",
        metavar="PLANT",
        help="plate problem file or name; or auto, dense, modal (the model's own plate)",
    )
    m.add_argument("--plant-scale", metavar="NAME=F,...", help="factors: moduli, skin, d33, damping, ...")
    m.add_argument("--hysteresis", type=float, metavar="W", help="patch hysteresis loop width (e.g. 0.15)")
    m.add_argument("--creep", type=float, metavar="C", help="patch creep gain, a fraction")
    m.add_argument("--sensor-bias", type=float, metavar="M", help="offset of every patch sensor, m")
    g = p.add_argument_group("lqr")
    g.add_argument("--r", type=float, metavar="R", help="LQR input weight R = r I, V^-2 (default 1e-14)")
    q = p.add_argument_group("qp")
    q.add_argument("--horizon", type=int, metavar="N", help="prediction horizon, steps")
    opt.add(q, "--solver", help=f"QP backend: {', '.join(BACKENDS)} ({BACKENDS[0]}, else {FALLBACK})")
    advanced(q.add_argument("--mode", metavar="MODE", help="closed-loop (receding horizon) or open-loop"))
    q.add_argument("--no-compare", action="store_true", help="skip the saturated-LQR comparison run")
    q.add_argument("--no-offset-free", action="store_true", help="no disturbance model (the QP before)")
    opt.add(p, "--max-memory")
    opt.add(p, "--force")
    p.add_argument("--no-plots", action="store_true", help="skip the figures")
    p.add_argument("--out", required=True, metavar="DIR", help=OUT_HELP)
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    p.set_defaults(func=run)


def _options(args) -> dict:
    lqr_opts = {"r": args.r}
    qp_opts = {"horizon": args.horizon, "solver": args.solver, "mode": args.mode}
    if args.no_offset_free:
        qp_opts["offset_free"] = False
    if args.method == "lqr":
        given = [f"--{k.replace('_', '-')}" for k, v in qp_opts.items() if v is not None]
        if given:
            raise InputError(f"{', '.join(given)}: apply to --method qp only")
        return {k: v for k, v in lqr_opts.items() if v is not None}
    if args.r is not None:
        raise InputError("--r: applies to --method lqr only")
    if args.horizon is not None and args.horizon < 1:
        raise InputError(f"horizon = {args.horizon!r}: expected a positive number of steps")
    return {k: v for k, v in qp_opts.items() if v is not None}


def _check(args) -> None:
    if args.shape not in SHAPES:
        raise InputError(f"shape = {args.shape!r}: expected one of {', '.join(SHAPES)}")
    if args.method not in METHODS:
        raise InputError(f"method = {args.method!r}: expected one of {', '.join(METHODS)}")
    for name in ("vmin", "vmax", "t_end", "period", "sensor_noise", "hysteresis", "creep", "sensor_bias"):
        v = getattr(args, name)
        if v is not None and not math.isfinite(v):
            raise InputError(f"{name.replace('_', '-')} = {v!r}: expected a finite number")
    if args.vmin is not None and args.vmax is not None and not args.vmin < args.vmax:
        raise InputError(f"vmin = {args.vmin!r}, vmax = {args.vmax!r}: expected vmin < vmax")
    if not args.t_end > 0:
        raise InputError(f"t-end = {args.t_end!r}: expected a positive duration (s)")
    if not args.period > 0 or args.period > args.t_end:
        raise InputError(f"period = {args.period!r}: expected a positive control period no longer than --t-end")
    check_seed(args.seed)
    if args.sensor_noise < 0:
        raise InputError(f"sensor-noise = {args.sensor_noise!r}: expected a standard deviation >= 0")


def run(args) -> int:
    _check(args)
    options = _options(args)
    with resources.long_runs(args.force, "--force"):
        summary = _morph(args, options)
    _print(summary, args)
    return 0


def _morph(args, options) -> dict:
    return morph_to_directory(
        args.problem,
        args.shape,
        args.method,
        args.out,
        nodes=parse_mesh(args.mesh) if args.mesh is not None else None,
        compare=not args.no_compare,
        plots=not args.no_plots,
        max_memory=resources.parse_size(args.max_memory) if args.max_memory else None,
        vmin=args.vmin,
        vmax=args.vmax,
        t_end=args.t_end,
        sensor_noise=args.sensor_noise,
        seed=args.seed,
        period=args.period,
        **_plant(args),
        **options,
    )


def _plant(args) -> dict:
    """``--plant`` (an integrator kind or a plant problem) and the plant-only options as morph's keywords."""
    out = {"plant": args.plant} if args.plant in PLANT_KINDS else {"plant_problem": args.plant}
    if args.plant_scale is not None:
        out["plant_scale"] = parse_plant_scale(args.plant_scale)
    if args.hysteresis is not None or args.creep is not None:
        out["actuator"] = HysteresisSettings(width=args.hysteresis or 0.0, creep=args.creep or 0.0)
    if args.sensor_bias is not None:
        out["sensor_bias"] = args.sensor_bias
    return out


def _print(summary: dict, args) -> None:
    if args.json:
        print(json.dumps(to_jsonable(summary)))
        return
    tip = summary["tip_corners_m"]
    lo, hi = summary["peak_voltage_V"]
    line = (
        f"{summary['shape']} / {summary['method']}: shape error {summary['shape_error']:.4f}, "
        f"tip corners {100 * tip[0]:+.2f} / {100 * tip[1]:+.2f} cm, voltages {lo:+.0f} .. {hi:+.0f} V, "
        f"{summary['wall_s']:.1f} s"
    )
    cmp = summary.get("compare_with")
    if summary.get("plant", "model") != "model":
        line += f" on plant {summary['plant']!r}"
    line += f" (plant's best {summary['plant_static_optimum_error']:.4f}, excess {summary['excess_error']:+.4f})"
    if cmp:
        line += f"; saturated lqr: shape error {cmp['shape_error']:.4f}"
    print(line + f" -> {args.out}")
