"""``wingopt identify``: load identification on the membrane from stretch-sensor series.

Either the simulated protocol (``--load L1|L2|L3|consistency --noise P --seed N``: truth on a finer
mesh, default 49x25, noise in percent of each sensor's peak output) or measured data
(``--data FILE.csv``). Writes ``summary.json``, ``load.csv``, ``lift.csv`` and figures into
``--out`` atomically (a failed run leaves no half-written directory).
"""

from __future__ import annotations

import argparse
import json
import re
import time

import numpy as np

from wingopt.errors import InputError
from wingopt.results import ResultDirectory, to_jsonable, write_csv, write_json

ORDER = 30

EXAMPLE = """noise convention: --noise is in PERCENT of each sensor's peak output (spec §2):
  --noise 1 is 1 %, --noise 5 is 5 %. Values between 0 and 0.1 look like fractions and are
  refused as ambiguous; write them with a percent sign to mean it (--noise 0.05%%).

examples:
  wingopt identify membrane --load L1 --noise 1 --seed 0 --method mhe --out runs/L1
  wingopt identify membrane --load L3 --noise 5 --seed 2 --load-space free --out runs/L3free
  wingopt identify membrane --load L2 --noise 1 --seed 0 --method jekf --out runs/L2jekf
  wingopt identify membrane --data wind_tunnel.csv --out runs/tunnel --json
  (CSV: header 't,S1,S2,S3,S4', time in s, dimensionless stretch; empty cells = missing samples)"""

GRID = (57, 29)
"""Points (x, y) of the uniform grid of ``load.csv``, edges included."""


def parse_noise(text: str) -> float:
    """``"1"`` or ``"1%"`` -> 0.01. Percent is the unit; bare values in (0, 0.1) are ambiguous."""
    s = str(text).strip()
    m = re.fullmatch(r"([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(%?)", s)
    if not m:
        raise InputError(f"noise = {text!r}: expected a percentage, e.g. 1 for 1 % (or '1%')")
    value, pct = float(m.group(1)), m.group(2) == "%"
    if not pct and 0 < value < 0.1:
        raise InputError(
            f"noise = {text!r}: ambiguous, the noise is in percent (1 means 1 %); "
            f"for {100 * value:g} % write {100 * value:g}, for {value:g} % write '{value:g}%'"
        )
    if value > 100:
        raise InputError(f"noise = {text!r}: expected a percentage between 0 and 100")
    return value / 100.0


def _mesh(text):
    from wingopt.problem import parse_mesh

    return parse_mesh(text)


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
    src.add_argument("--load", choices=("L1", "L2", "L3", "consistency"), help="simulate this load case")
    src.add_argument("--data", metavar="FILE.csv", help="measured series: t column + one column per sensor")
    p.add_argument("--noise", default="1", help="simulated noise in PERCENT of each sensor's peak (default 1)")
    p.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    p.add_argument("--truth-mesh", default="49x25", help="mesh of the simulated truth (default 49x25)")
    p.add_argument("--same-mesh", action="store_true", help="seed protocol: simulate the truth on the estimator's mesh")
    p.add_argument("--t-end", type=float, default=1.0, help="simulated duration, s (default 1)")
    p.add_argument("--mesh", help="estimator mesh NXxNY (default: the problem's)")
    p.add_argument(
        "--method",
        choices=("mhe", "jekf", "jekf-tuned"),
        default="mhe",
        help="estimator: mhe (default); jekf = the seed's filter (200 Pa prior, R = 1e-4, lambda tuned on the "
        "noise-free truth as the seed did, a default lambda on measured data); jekf-tuned = zero initial load, "
        "lambda from the data",
    )
    g = p.add_argument_group("moving-horizon estimator")
    g.add_argument("--backend", choices=("numpy", "cvxpy", "ipopt"), default="numpy", help="window solver")
    g.add_argument("--qp-solver", choices=("clarabel", "osqp"), default="clarabel", help="QP solver of cvxpy")
    g.add_argument("--load-space", choices=("fixed", "free"), default="fixed", help="load basis (default fixed)")
    g.add_argument(
        "--state-prior",
        default="1",
        help="prior std of the initial modal state relative to the data's amplitude (default 1: weak), or "
        "'evidence': chosen among 1, 0.1, 0.01, 0.001 by the first window's evidence (helps --load-space free)",
    )
    g.add_argument("--window", type=int, default=200, help="window length, samples (default 200)")
    g.add_argument("--stride", type=int, default=50, help="samples per window step (default 50)")
    g.add_argument("--load-model", choices=("constant", "random_walk"), default="constant")
    g.add_argument("--lambda", dest="lam", type=float, help="fixed Tikhonov weight (default: from the data)")
    g.add_argument("--lambda-rule", choices=("robust", "discrepancy", "gcv"), default="robust")
    g.add_argument("--modes", type=int, default=40, help="membrane modes kept (default 40)")
    g.add_argument("--pressure-bounds", nargs=2, type=float, metavar=("MIN", "MAX"), help="Pa (cvxpy/ipopt)")
    p.add_argument("--initial-load", type=float, help="sign prior, Pa (default: the problem's initial_load)")
    p.add_argument("--noise-std", type=float, help="sensor noise std (default: estimated from the data)")
    p.add_argument("--no-plots", action="store_true", help="skip the figures")
    p.add_argument("--out", required=True, help="output directory (replaced atomically)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    p.set_defaults(func=run)


def state_prior_settings(text: str) -> dict:
    """``MHESettings`` fields of a ``--state-prior`` value: a positive number or ``evidence``."""
    from wingopt.estimation.mhe import STATE_PRIOR_EVIDENCE

    if text.strip().lower() == "evidence":
        return {"state_prior_choices": STATE_PRIOR_EVIDENCE}
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (np.isfinite(value) and value > 0):
        raise InputError(f"--state-prior {text!r}: expected a positive number or 'evidence'")
    return {"state_prior": value}


def _settings(args):
    from wingopt.estimation.mhe import MHESettings

    return MHESettings(
        **state_prior_settings(args.state_prior),
        window=args.window,
        stride=args.stride,
        load_model=args.load_model,
        modes=args.modes,
        load_space=args.load_space,
        backend=args.backend,
        qp_solver=args.qp_solver,
        regularization=args.lam,
        lambda_rule=args.lambda_rule,
        pressure_bounds=tuple(args.pressure_bounds) if args.pressure_bounds else None,
    )


def run(args) -> int:
    from wingopt.estimation.csv_data import read_measurements
    from wingopt.estimation.studies import CleanCases, evaluate, load_field, protocol_sign, run_method
    from wingopt.membrane import MembraneModel
    from wingopt.problem import load_problem, parse_mesh
    from wingopt.results.writer import check_writable

    check_writable(args.out)
    problem = load_problem(args.problem)
    if problem.kind != "membrane":
        raise InputError(f"problem = {args.problem!r}: identify needs a membrane problem, got kind {problem.kind!r}")
    if args.mesh:
        problem = problem.with_mesh(parse_mesh(args.mesh))
    settings = _settings(args) if args.method == "mhe" else None
    if args.method != "mhe" and (args.backend != "numpy" or args.load_space != "fixed" or args.state_prior != "1"):
        raise InputError("--backend, --load-space and --state-prior apply to --method mhe only")
    model = MembraneModel.from_problem(problem)
    summary: dict = {"problem": problem.name, "method": args.method, "mesh": list(problem.nodes)}
    case = None
    initial_load = args.initial_load
    if args.load:
        noise = parse_noise(args.noise)
        if not args.t_end > 0:
            raise InputError(f"t-end = {args.t_end!r}: expected a positive duration (s)")
        truth_nodes = None if args.same_mesh else parse_mesh(args.truth_mesh)
        case = CleanCases(problem, truth_nodes, args.t_end).case(args.load, noise, args.seed)
        # The estimators are not told the simulated noise level: they estimate it from the data
        # (or take --noise-std), as they would have to with measurements.
        meas = _with_noise(case.measurements, args.noise_std)
        if initial_load is None:
            initial_load = protocol_sign(args.load) * abs(problem.identification.initial_load)
        summary.update(
            load_case=args.load,
            noise_percent=100 * noise,
            seed=args.seed,
            truth_mesh=list(truth_nodes or problem.nodes),
            protocol="same-mesh (seed)" if args.same_mesh else "fine-mesh truth",
        )
    else:
        meas, report = read_measurements(args.data, problem.sensor_names)
        summary["data"] = report.as_dict()
        meas = _with_noise(meas, args.noise_std)
    t0 = time.perf_counter()
    result = run_method(
        "mhe" if args.method == "mhe" else ("jekf-tuned" if args.method == "jekf-tuned" else "jekf-seed"),
        model,
        meas,
        settings,
        initial_load=initial_load,
        truth=case,
    )
    wall = time.perf_counter() - t0
    lift = float(result.lift[-1])
    std = None if result.lift_std is None else float(result.lift_std[-1])
    summary.update(
        lift_N=lift,
        lift_std_N=std,
        wall_s=wall,
        regularization=result.regularization,
        samples=int(meas.count),
        missing_samples=int(np.count_nonzero(meas.missing)),
        estimator=to_jsonable({k: v for k, v in result.info.items() if k not in ("iterations_per_window",)}),
    )
    if case is not None:
        rec = evaluate(case, result, model, args.method)
        summary.update(
            load_error=rec.load_error,
            deflection_error=rec.deflection_error,
            true_lift_N=rec.true_lift,
            lift_error=rec.lift_error,
            lift_error_note="|lift - true lift| / ∫|P| (L2 has no net lift)",
            sign_ok=rec.sign_ok,
        )
    P = load_field(result, model)
    xs = np.linspace(0, problem.width, GRID[0])
    ys = np.linspace(0, problem.height, GRID[1])
    X, Y = np.meshgrid(xs, ys)
    Pg = P(X, Y)
    with ResultDirectory(args.out) as tmp:
        write_json(tmp / "summary.json", summary)
        write_csv(tmp / "load.csv", ["x", "y", "pressure_Pa"], zip(X.ravel(), Y.ravel(), Pg.ravel()))
        if result.lift_std is not None:
            write_csv(tmp / "lift.csv", ["t", "lift_N", "lift_std_N"], zip(result.t, result.lift, result.lift_std))
        else:
            write_csv(tmp / "lift.csv", ["t", "lift_N"], zip(result.t, result.lift))
        if not args.no_plots:
            _plots(tmp, result, model, case, X, Y, Pg, summary)
    _print(summary, args)
    return 0


def _with_noise(meas, std):
    """The measurements with the noise level ``std`` (``None``: unknown, to be estimated)."""
    import dataclasses

    if std is None:
        return dataclasses.replace(meas, noise_std=None)
    if not (np.isfinite(std) and std > 0):
        raise InputError(f"noise-std = {std!r}: expected a positive number (sensor output units)")
    return dataclasses.replace(meas, noise_std=np.full(len(meas.sensor_names), float(std)))


def _plots(tmp, result, model, case, X, Y, Pg, summary) -> None:
    from wingopt.estimation.studies import load_field
    from wingopt.plots.identify import plot_errors, plot_lift, plot_load_field

    truth = case.load(X, Y) if case is not None else None
    title = f"{summary.get('load_case', 'data')} · {summary['method']}"
    first = None
    if result.method == "mhe":
        first = float(result.t[min(result.info["window"], result.t.size) - 1] - result.t[0])
    plot_load_field(tmp / "load_field.png", X, Y, Pg, truth, title)
    true_lift = case.true_lift if case else None
    plot_lift(tmp / "lift.png", result.t, result.lift, result.lift_std, true_lift, title, first)
    if case is not None:
        # Error histories on a subsample of the times (each needs two integrals on the truth mesh).
        idx = np.unique(np.linspace(0, result.t.size - 1, 41).astype(int))
        t_case = case.trajectory.t
        le, de = [], []
        for k in idx:
            kt = int(np.argmin(np.abs(t_case - result.t[k])))
            le.append(case.load_error(load_field(result, model, k)))
            de.append(case.deflection_error(model.field(result.deflection[k]), kt))
        plot_errors(tmp / "errors.png", result.t[idx], np.array(le), np.array(de), title, first)


def _print(summary: dict, args) -> None:
    if args.json:
        print(json.dumps(to_jsonable(summary)))
        return
    line = f"{summary['method']}: lift {summary['lift_N']:.5g} N"
    if summary.get("lift_std_N") is not None:
        line += f" ± {summary['lift_std_N']:.2g}"
    if "load_error" in summary:
        line += (
            f", load error {summary['load_error']:.4f}, deflection error {summary['deflection_error']:.2e}"
            f" (true lift {summary['true_lift_N']:.5g} N)"
        )
    line += f", {summary['wall_s']:.2f} s -> {args.out}"
    print(line)
