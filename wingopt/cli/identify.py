"""``wingopt identify``: load identification on the membrane from stretch-sensor series.

Either the simulated protocol (``--load L1|L2|L3|consistency --noise P --seed N``: truth on a finer
mesh, default 49x25, noise in percent of each sensor's peak output) or measured data
(``--data FILE.csv``). Writes ``summary.json``, ``load.csv``, ``lift.csv`` and figures into
``--out`` atomically (a failed run leaves no half-written directory).
"""

from __future__ import annotations

import json
import os

from wingopt.cli import OUT_HELP, follow, warnings_printed
from wingopt.cli import options as opt
from wingopt.cli.helptext import Formatter, add_help_all, advanced
from wingopt.cli.options import parse_noise
from wingopt.errors import InputError
from wingopt.estimation.registry import FRAME_METHODS, METHOD_ALIASES, METHODS, MODEL_ALIASES, MODELS
from wingopt.optim.registry import solver_names
from wingopt.results import to_jsonable
from wingopt.workflows.protocols import TRUTHS

ORDER = 30

USAGE = """%(prog)s PROBLEM --out DIR [options]
       (--load CASE | --data FILE.csv | --follow FILE.csv | --dic DIR|FILE.npz)"""

EXAMPLE = """examples (more, and every option explained, in docs/cli.md):
  wingopt identify membrane --load L1 --noise 1 --seed 0 --out runs/L1
  wingopt identify cal.toml --data examples/data/tunnel_300Hz.csv --out runs/t"""

METHOD_HELP = (
    "auto (default), batch (whole-record fit; steady on a loaded record; alias realistic), mhe (moving "
    "horizon), jekf-seed (alias jekf), jekf-tuned, ekf (stream), fullfield (DIC full field)"
)


def register(sub, common) -> None:
    p = sub.add_parser(
        "identify",
        parents=[common],
        help="identify the membrane load and its lift (every estimator: batch, mhe, jekf, ekf, fullfield)",
        usage=USAGE,
        description="Estimate the membrane wing's pressure field and its lift, with a band (1 sd).",
        epilog=EXAMPLE,
        formatter_class=Formatter,
    )
    add_help_all(p)
    p.add_argument("problem", help="problem file (.toml) or built-in name (membrane)")
    _add_sources(p)
    p.add_argument("--out", required=True, metavar="DIR", help=OUT_HELP)
    _add_estimator_choice(p)
    _add_simulation_options(p)
    _add_estimator_options(p)
    opt.add(p, "--max-memory")
    opt.add(p, "--force")
    opt.add(p, "--no-plots")
    opt.add(p, "--json")
    data = opt.add_channel_options(p)
    follow.add_options(data)
    p.set_defaults(func=run)


def _add_sources(p) -> None:
    """Where the record comes from: one of a simulated case, a sensor file, a growing CSV, DIC frames."""
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--load",
        choices=("L1", "L2", "L3", "consistency", "LE"),
        metavar="CASE",
        help="simulated case: L1, L2, L3, LE, consistency",
    )
    src.add_argument("--data", metavar="FILE.csv", help="sensor record: t, S1, S2, ... ('-': standard input)")
    src.add_argument("--follow", metavar="FILE.csv", help="stream a CSV that grows: one estimate per row")
    src.add_argument("--dic", metavar="DIR|FILE.npz", help="DIC frames (DICe, CSV or NPZ; docs/dic.md)")


def _add_estimator_choice(p) -> None:
    """The estimator's mesh, method and membrane (the registry's pair), and the MHE's FvK cross-check."""
    opt.add(p, "--mesh", help="estimator mesh (default: the problem's)")
    opt.add(p, "--method", choices=METHODS + tuple(METHOD_ALIASES), default="auto", help=METHOD_HELP)
    p.add_argument(
        "--model",
        choices=MODELS + tuple(MODEL_ALIASES),
        default="auto",
        metavar="NAME",
        help="membrane: auto, fvk, berger (nonlinear), linear",
    )
    advanced(
        p.add_argument(
            "--no-model-form",
            dest="model_form",
            action="store_const",
            const=False,
            help="mhe: do not cross-check a flagged result with the FvK estimator (faster; the band then covers "
            "only the misfit, not the model's bias)",
        )
    )


def _add_simulation_options(p) -> None:
    """The simulated case's options: unset is None, so that one given with measured data is refused by name."""
    t = p.add_argument_group("simulated case (--load only; refused with --data, --dic, --follow)")
    t.add_argument("--noise", dest="noise", metavar="PERCENT", help="noise, %% of each peak (default 1)")
    advanced(t.add_argument("--noise-percent", dest="noise", metavar="PERCENT", help="the same as --noise"))
    opt.add(t, "--seed", default=None)
    opt.add(t, "--truth-mesh", default=None)
    same = "seed protocol: simulate the truth on the estimator's mesh"
    advanced(t.add_argument("--same-mesh", action="store_true", default=None, help=same))
    opt.add(t, "--t-end", help="simulated duration, s (default 1)")
    t.add_argument("--truth", choices=TRUTHS, metavar="NAME", help="truth membrane: linear (default), berger, fvk")
    advanced(
        t.add_argument("--truth-prestrain", nargs=2, type=float, metavar=("EX", "EY"), help="truth prestrain (file's)")
    )
    advanced(t.add_argument("--truth-damping", type=float, metavar="X", help="truth damping factor (default 1)"))
    t.add_argument("--gust", action="store_true", default=None, help="1-cos gust: +60 %% over 0.2 s from 0.4 s")


def _add_estimator_options(p) -> None:
    """The estimators' options (each refused by an estimator that does not use it: the registry's check)."""
    g = p.add_argument_group("estimator options (refused by an estimator that does not use them)")
    opt.add(g, "--solver", choices=solver_names("window"), help="mhe window solver (numpy)", aliases=("--backend",))
    advanced(
        g.add_argument(
            "--qp-solver", choices=solver_names("least-distance"), help="QP solver of --solver cvxpy (clarabel)"
        )
    )
    advanced(g.add_argument("--load-space", choices=("fixed", "free"), help="mhe load basis (default fixed)"))
    advanced(
        g.add_argument(
            "--state-prior",
            metavar="S|evidence",
            help="mhe: prior std of the initial modal state relative to the data's amplitude (default 1: weak), "
            "or 'evidence': chosen among 1, 0.1, 0.01, 0.001 by the first window's evidence",
        )
    )
    g.add_argument("--window", metavar="TIME", help="mhe window: 0.2s, 200ms or samples (default 0.2s)")
    g.add_argument("--stride", metavar="TIME", help="mhe window step, as --window (default 0.05s)")
    g.add_argument(
        "--load-model",
        choices=("auto", "constant", "varying", "random_walk", "gust"),
        metavar="NAME",
        help="auto, constant, varying (random_walk, gust)",
    )
    advanced(
        g.add_argument(
            "--load-timescale",
            type=float,
            metavar="S",
            help="mhe --load-model varying: time (s) over which the load's amplitude may change by its own size (1)",
        )
    )
    advanced(
        g.add_argument(
            "--no-consistency",
            dest="consistency",
            action="store_const",
            const=False,
            help="mhe: do not skip an unexplained start (load onset) nor restart on data inconsistent with it",
        )
    )
    g.add_argument("--lambda", dest="lam", type=float, metavar="X", help="fixed Tikhonov weight (mhe, jekf)")
    g.add_argument("--lambda-rule", metavar="NAME", help="rule choosing lambda (docs/formulations.md)")
    g.add_argument("--modes", type=int, metavar="N", help="membrane modes kept (mhe 40, batch 48)")
    advanced(
        g.add_argument("--pressure-bounds", nargs=2, type=float, metavar=("MIN", "MAX"), help="Pa (mhe, cvxpy/ipopt)")
    )
    advanced(g.add_argument("--initial-load", type=float, metavar="PA", help="sign prior, Pa (default: the problem's)"))
    opt.add(g, "--noise-std")


def identify_options(args):
    """The :class:`~wingopt.estimation.options.IdentifyOptions` of the command line (unset: ``None``)."""
    from wingopt.estimation.options import IdentifyOptions
    from wingopt.values import LambdaChoice

    lam = None if args.lam is None and args.lambda_rule is None else LambdaChoice(args.lam, args.lambda_rule)
    return IdentifyOptions(
        lam=lam,
        window=args.window,
        stride=args.stride,
        solver=args.solver,
        qp_solver=args.qp_solver,
        modes=args.modes,
        load_model=args.load_model,
        load_timescale=args.load_timescale,
        state_prior=args.state_prior,
        pressure_bounds=tuple(args.pressure_bounds) if args.pressure_bounds else None,
        load_space=args.load_space,
        consistency=args.consistency,
        noise_std=args.noise_std,
        initial_load=args.initial_load,
        model_form=args.model_form,
    )


def run(args) -> int:
    from wingopt import resources

    with resources.long_runs(args.force, "--force"):
        return _run(args)


def _run(args) -> int:
    from wingopt.problem import load_problem, parse_mesh
    from wingopt.resources import parse_size
    from wingopt.results.writer import check_writable
    from wingopt.workflows.identify import identify, write_identify_outputs

    cpu0 = sum(os.times()[:4])  # the estimate's CPU time, this process and its children
    check_writable(args.out, inputs=[("--data", args.data), ("--follow", args.follow), ("problem", args.problem)])
    options = identify_options(args)
    problem = load_problem(args.problem)
    if problem.kind != "membrane":
        raise InputError(f"problem = {args.problem!r}: identify needs a membrane problem, got kind {problem.kind!r}")
    channels = opt.channel_map(args, problem)
    if channels is not None and not (args.data or args.follow):
        raise InputError("--columns/--gain/--offset/--time-column/--time-unit: apply to --data or --follow only")
    simulated = simulated_case(args)
    check_sizes(args, parse_mesh(args.mesh) if args.mesh is not None else problem.nodes)
    if follow.wants_stream(args):
        return follow.run_stream(args, options, channels)
    run_ = identify(
        problem,
        load=args.load,
        data=args.data,
        dic=args.dic,
        method=args.method,
        model=args.model,
        options=options,
        nodes=parse_mesh(args.mesh) if args.mesh is not None else None,
        max_memory=parse_size(args.max_memory) if args.max_memory else None,
        channels=channels if args.data else None,
        **simulated,
    )
    write_identify_outputs(run_, args.out, plots=not args.no_plots)
    cpu = os.times()
    cpu_s = cpu.user + cpu.system + cpu.children_user + cpu.children_system - cpu0
    _print(to_jsonable(run_.summary()), args, cpu_s)  # its warnings were logged once, as they arose
    return 0


OUT_NAME_SPARE = 32
"""Bytes the result writer adds to the ``--out`` name for its hidden work directory
(``.NAME.tmp-PID-XXXXXXXX``, :mod:`wingopt.results.writer`)."""


def check_sizes(args, nodes: tuple[int, int]) -> None:
    """Refuse, before any stage starts, what the run would refuse only later: more ``--modes`` than
    the mesh has, a ``--stride`` longer than the ``--window`` (default 0.2 s), an ``--out`` name the
    file system cannot hold with the writer's work-directory suffix."""
    from wingopt.estimation.options import parse_duration
    from wingopt.resources import membrane_dofs

    dofs = membrane_dofs(nodes)
    if args.modes is not None and not 1 <= args.modes <= dofs:
        raise InputError(f"--modes {args.modes}: expected 1..{dofs} (the {nodes[0]}x{nodes[1]} mesh's dofs)")
    if args.stride is not None:
        stride = parse_duration(args.stride, "--stride")
        window = parse_duration(args.window if args.window is not None else "0.2s", "--window")
        if type(stride) is type(window) and stride > window:  # both seconds or both samples
            given = args.window if args.window is not None else "0.2s (the default)"
            raise InputError(f"--stride {args.stride}: longer than the window, {given}: expected at most the window")
    name = os.path.basename(os.path.normpath(str(args.out)))
    parent = os.path.dirname(os.path.abspath(str(args.out)))
    try:
        limit = os.pathconf(parent if os.path.isdir(parent) else ".", "PC_NAME_MAX")
    except (OSError, ValueError):
        limit = 255
    if len(os.fsencode(name)) + OUT_NAME_SPARE > limit:
        raise InputError(
            f"--out: the name {name[:20]!r}... is {len(os.fsencode(name))} bytes: expected at most "
            f"{limit - OUT_NAME_SPARE} (the file system's {limit}, less the work directory's suffix)"
        )


SIMULATION_FLAGS = {
    "noise": "--noise",
    "seed": "--seed",
    "truth": "--truth",
    "truth_mesh": "--truth-mesh",
    "same_mesh": "--same-mesh",
    "truth_prestrain": "--truth-prestrain",
    "truth_damping": "--truth-damping",
    "t_end": "--t-end",
    "gust": "--gust",
}
"""The options of a simulated case (``--load``): given with measured data or frames they are refused."""


def simulated_case(args) -> dict:
    """The simulation-only options given, as :func:`wingopt.identify`'s keywords (refused without ``--load``)."""
    from wingopt.membrane.loads import Gust
    from wingopt.problem import parse_mesh

    given = [flag for name, flag in SIMULATION_FLAGS.items() if getattr(args, name) is not None]
    if not args.load:
        if given:
            source = "--dic" if args.dic else "--follow" if args.follow else "--data"
            raise InputError(f"{', '.join(given)}: simulation-only option(s), used with --load only, not with {source}")
        return {}
    if args.t_end is not None and not args.t_end > 0:
        raise InputError(f"t-end = {args.t_end!r}: expected a positive duration (s)")
    kw = {
        "noise_percent": None if args.noise is None else parse_noise(args.noise) * 100,
        "seed": args.seed,
        "truth": args.truth,
        "truth_nodes": None if args.truth_mesh is None else parse_mesh(args.truth_mesh),
        "truth_prestrain": tuple(args.truth_prestrain) if args.truth_prestrain else None,
        "truth_damping": args.truth_damping,
        "t_end": args.t_end,
        "gust": Gust() if args.gust else None,
    }
    kw = {k: v for k, v in kw.items() if v is not None}
    if args.same_mesh:
        kw["truth_nodes"] = None  # the seed's same-mesh protocol (over --truth-mesh)
    return kw


def route_words(summary: dict) -> str:
    """What ran, in words: the route (steady, transient, full field, stream) and the estimator; for
    DIC frames, how many frames of how many points and that the lift is the steady fit of their mean."""
    route, method = summary.get("route"), summary["method"]
    if not route:
        return method
    est = summary.get("estimator") or {}
    frames = est.get("frames") if isinstance(est.get("frames"), dict) else None
    if method in FRAME_METHODS and frames:
        what = f"{route}, {frames.get('used', frames.get('total'))} frames x {frames.get('points')} points"
        if est.get("steady_lift_N") is not None and est["steady_lift_N"] == summary["lift_N"]:
            what += ", steady fit of their mean"
        return what
    return f"{route} ({method})"


def _print(summary: dict, args, cpu_s: float | None = None) -> None:
    """The run in one line: route and estimator, lift ± 1 sd, status, errors (simulated), CPU and wall
    time, output, and how many warning lines were printed above."""
    if args.json:
        print(json.dumps(to_jsonable(summary)))
        return
    line = route_words(summary)
    line += f": lift {summary['lift_N']:.5g} N"
    if summary.get("lift_std_N") is not None:
        line += f" ± {summary['lift_std_N']:.2g} N (1 sd)"
    if summary.get("status"):
        line += f" [{summary['status']}]"  # whether to trust it, before the numbers that say how well
    if "load_error" in summary:
        line += (
            f", load error {summary['load_error']:.4f}, deflection error {summary['deflection_error']:.2e}"
            f" (true lift {summary['true_lift_N']:.5g} N)"
        )
    if cpu_s is not None:
        line += f", {cpu_s:.3g} s CPU"
    line += f", {summary['wall_s']:.3g} s wall -> {args.out}"
    printed = warnings_printed()
    if printed:
        line += f" ({printed} warning{'s' * (printed != 1)} above; summary.json lists them)"
    print(line)
