"""``wingopt identify``: load identification on the membrane from stretch-sensor series.

Either the simulated protocol (``--load L1|L2|L3|consistency --noise P --seed N``: truth on a finer
mesh, default 49x25, noise in percent of each sensor's peak output) or measured data
(``--data FILE.csv``). Writes ``summary.json``, ``load.csv``, ``lift.csv`` and figures into
``--out`` atomically (a failed run leaves no half-written directory).
"""

from __future__ import annotations

import argparse
import json

from wingopt.cli import OUT_HELP, follow
from wingopt.cli import options as opt
from wingopt.cli.options import parse_noise
from wingopt.errors import InputError
from wingopt.estimation.registry import METHOD_ALIASES, METHODS, MODEL_ALIASES, MODELS
from wingopt.optim.registry import solver_names
from wingopt.results import to_jsonable
from wingopt.workflows.protocols import TRUTHS

ORDER = 30

EXAMPLE = """noise convention: --noise is in PERCENT of each sensor's peak output (spec §2):
  --noise 1 is 1 %, --noise 5 is 5 %. Values between 0 and 0.1 look like fractions and are
  refused as ambiguous; write them with a percent sign to mean it (--noise 0.05%%).

examples:
  wingopt identify membrane --load L1 --noise 1 --seed 0 --method mhe --out runs/L1
  wingopt identify membrane --load L3 --noise 5 --seed 2 --load-space free --out runs/L3free
  wingopt identify membrane --load L2 --noise 1 --seed 0 --method jekf-seed --out runs/L2jekf
  wingopt identify membrane --data wind_tunnel.csv --out runs/tunnel --json   # FvK membrane, tension identified
  wingopt identify cal.toml --data examples/data/tunnel_300Hz.csv --out runs/tunnel   # after wingopt calibrate
  wingopt identify membrane --data wind_tunnel.csv --model linear --out runs/lin   # the seed's linear MHE
  wingopt identify membrane --follow daq.csv --print-every 100 --idle-timeout 5 --out runs/live
  daq_reader | wingopt identify membrane --data - --out runs/live
  wingopt identify membrane --load LE --truth fvk --truth-prestrain 0.06 0.04 --truth-damping 2 --out runs/fvk
  wingopt identify membrane --load LE --truth berger --truth-prestrain 0.06 0.04 --out runs/real
  wingopt identify membrane --load L1 --truth berger --gust --out runs/gust
  wingopt identify membrane --data gusty.csv --load-model random_walk --load-timescale 0.5 --out runs/gust
  wingopt identify membrane --data daq.csv --time-column time_s --columns S1=ch1,S2=ch2,S3=ch3,S4=ch4 \\
      --gain 1e-5 --offset 250 --out runs/daq   # stretch = gain * (raw - offset)
  (a record that starts loaded, without a release transient, takes the steady route: the sensors' mean and the
  flow's buffeting; [identification] pressure_prior and leading_edge declare the flow, docs/tunnel.md)
  (CSV: header 't,S1,S2,S3,S4', time in s, dimensionless stretch; empty cells = missing samples; a DAQ's own
  columns and units: --columns, --gain, --offset (stretch = gain * (raw - offset)) or the problem's [measurements])"""


def register(sub, common) -> None:
    p = sub.add_parser(
        "identify",
        parents=[common],
        help="identify the membrane load from stretch sensors (MHE or JEKF)",
        description="Estimate the pressure field and its lift on the membrane wing from stretch-sensor "
        "time series: the simulated protocol (--load) or measured data (--data FILE.csv).",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("problem", help="problem file (.toml) or built-in name (membrane)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--load", choices=("L1", "L2", "L3", "consistency", "LE"), help="simulate this load case (LE: leading edge)"
    )
    src.add_argument(
        "--data", metavar="FILE.csv", help="measured series: t column + one column per sensor ('-': stream from stdin)"
    )
    src.add_argument(
        "--follow", metavar="FILE.csv", help="stream a CSV that grows: one estimate per sample as rows arrive"
    )
    src.add_argument(
        "--dic", metavar="DIR|FILE.npz", help="DIC frames: the full-field estimator (another --method: virtual sensors)"
    )
    p.add_argument(
        "--noise",
        "--noise-percent",
        dest="noise",
        default="1",
        help="simulated noise in PERCENT of each sensor's peak (default 1; Python: noise_percent)",
    )
    opt.add(p, "--seed")
    opt.add(p, "--truth-mesh")
    p.add_argument("--same-mesh", action="store_true", help="seed protocol: simulate the truth on the estimator's mesh")
    opt.add(p, "--t-end", default=1.0, help="simulated duration, s (default 1)")
    opt.add(p, "--mesh", help="estimator mesh NXxNY (default: the problem's)")
    p.add_argument(
        "--method",
        choices=METHODS + tuple(METHOD_ALIASES),
        default="auto",
        help="estimator: auto (default: batch on --data and on nonlinear truth, mhe on the seed's linear "
        "protocol, ekf on streams); mhe = the seed protocol's moving-horizon estimator (linear membrane); "
        "batch = whole-record fit with prestrains and damping identified (berger or fvk membrane); "
        "jekf-seed (alias jekf) = the seed's filter; jekf-tuned = zero initial load, lambda from the data; "
        "ekf = the streaming filter of the batch model",
    )
    p.add_argument(
        "--model",
        choices=MODELS + tuple(MODEL_ALIASES),
        default="auto",
        help="membrane the estimator assumes: fvk (Foppl-von Karman), berger (uniform tension; alias "
        "nonlinear), linear (the seed's); auto (default) follows --method and the data "
        "(docs/estimation_realistic.md). Options the chosen pair does not use are refused.",
    )
    p.add_argument(
        "--no-model-form",
        dest="model_form",
        action="store_const",
        const=False,
        help="mhe: do not cross-check a flagged result with the FvK estimator (faster; the band then covers "
        "only the misfit, not the model's bias)",
    )
    t = p.add_argument_group("simulated truth (--load)")
    t.add_argument(
        "--truth",
        choices=TRUTHS,
        default="linear",
        help="truth membrane: linear (default, the seed's protocol), berger, fvk (Foppl-von Karman, high fidelity)",
    )
    t.add_argument("--truth-prestrain", nargs=2, type=float, metavar=("EX", "EY"), help="truth prestrain (file's)")
    t.add_argument("--truth-damping", type=float, default=1.0, help="truth damping factor (default 1)")
    t.add_argument("--gust", action="store_true", help="1-cos gust on the load: +60 %% over 0.2 s from t = 0.4 s")
    g = p.add_argument_group("estimator options (each refused by an estimator that does not use it)")
    opt.add(g, "--solver", choices=solver_names("window"), help="mhe window solver (numpy)", aliases=("--backend",))
    g.add_argument("--qp-solver", choices=solver_names("least-distance"), help="QP solver of --solver cvxpy (clarabel)")
    g.add_argument("--load-space", choices=("fixed", "free"), help="mhe load basis (default fixed)")
    g.add_argument(
        "--state-prior",
        help="mhe: prior std of the initial modal state relative to the data's amplitude (default 1: weak), or "
        "'evidence': chosen among 1, 0.1, 0.01, 0.001 by the first window's evidence (helps --load-space free)",
    )
    g.add_argument(
        "--window",
        help="mhe window length: seconds with a unit (0.2s, 200ms) or a whole number of samples (200); "
        "default 0.2s (200 samples at 1 kHz, 60 at 300 Hz)",
    )
    g.add_argument("--stride", help="mhe window step, same units as --window (default 0.05s)")
    g.add_argument(
        "--load-model",
        choices=("auto", "constant", "varying", "random_walk", "gust"),
        help="constant: a steady load; varying (aliases random_walk, gust): a load that follows gusts (mhe: random "
        "walk with --load-timescale; batch: a gust amplitude); auto (the batch default): varying only when the "
        "constant load misfits",
    )
    g.add_argument(
        "--load-timescale",
        type=float,
        help="mhe --load-model varying: time (s) over which the load's amplitude may change by its own size (1)",
    )
    g.add_argument(
        "--no-consistency",
        dest="consistency",
        action="store_const",
        const=False,
        help="mhe: do not skip an unexplained start (load onset) nor restart on data inconsistent with the estimate",
    )
    p.add_argument("--lambda", dest="lam", type=float, help="fixed Tikhonov weight (mhe, jekf; default: from the data)")
    p.add_argument(
        "--lambda-rule",
        help="data-only rule choosing lambda: mhe knee (default), morozov, gcv; jekf-tuned late-innovation-lr "
        "(default), prediction-evidence, quasi-optimality (docs/formulations.md)",
    )
    g.add_argument("--modes", type=int, help="membrane modes kept (mhe 40, batch and ekf 48, jekf all)")
    g.add_argument("--pressure-bounds", nargs=2, type=float, metavar=("MIN", "MAX"), help="Pa (mhe, cvxpy/ipopt)")
    p.add_argument("--initial-load", type=float, help="sign prior, Pa (default: the problem's initial_load)")
    opt.add(p, "--noise-std")
    opt.add(p, "--max-memory")
    opt.add(p, "--force")
    opt.add(p, "--no-plots")
    p.add_argument("--out", required=True, help=OUT_HELP)
    opt.add(p, "--json")
    opt.add_channel_options(p)
    follow.add_options(p)
    p.set_defaults(func=run)


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

    check_writable(args.out, inputs=[("--data", args.data), ("--follow", args.follow), ("problem", args.problem)])
    options = identify_options(args)
    problem = load_problem(args.problem)
    if problem.kind != "membrane":
        raise InputError(f"problem = {args.problem!r}: identify needs a membrane problem, got kind {problem.kind!r}")
    channels = opt.channel_map(args, problem)
    if channels is not None and not (args.data or args.follow):
        raise InputError("--columns/--gain/--offset/--time-column/--time-unit: apply to --data or --follow only")
    if follow.wants_stream(args):
        return follow.run_stream(args, options, channels)
    if args.load and not args.t_end > 0:
        raise InputError(f"t-end = {args.t_end!r}: expected a positive duration (s)")
    run_ = identify(
        problem,
        load=args.load,
        noise_percent=parse_noise(args.noise) * 100 if args.load else 1.0,
        seed=args.seed,
        data=args.data,
        dic=args.dic,
        method=args.method,
        model=args.model,
        options=options,
        truth_nodes=None if args.same_mesh else parse_mesh(args.truth_mesh),
        t_end=args.t_end,
        nodes=parse_mesh(args.mesh) if args.mesh is not None else None,
        max_memory=parse_size(args.max_memory) if args.max_memory else None,
        truth=args.truth,
        truth_prestrain=tuple(args.truth_prestrain) if args.truth_prestrain else None,
        truth_damping=args.truth_damping,
        gust=_gust() if args.gust else None,
        channels=channels if args.data else None,
    )
    write_identify_outputs(run_, args.out, plots=not args.no_plots)
    _print(to_jsonable(run_.summary()), args)  # its warnings were logged once, as they arose
    return 0


def _gust():
    from wingopt.membrane.loads import Gust

    return Gust()


def _print(summary: dict, args) -> None:
    if args.json:
        print(json.dumps(to_jsonable(summary)))
        return
    line = f"{summary['method']}: lift {summary['lift_N']:.5g} N"
    if summary.get("lift_std_N") is not None:
        line += f" ± {summary['lift_std_N']:.2g}"
    if summary.get("status"):
        line += f" [{summary['status']}]"  # whether to trust it, before the numbers that say how well
    if "load_error" in summary:
        line += (
            f", load error {summary['load_error']:.4f}, deflection error {summary['deflection_error']:.2e}"
            f" (true lift {summary['true_lift_N']:.5g} N)"
        )
    line += f", {summary['wall_s']:.2f} s -> {args.out}"
    if summary.get("warnings"):
        line += f" ({len(summary['warnings'])} warning(s): see above and summary.json)"
    print(line)
