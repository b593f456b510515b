"""Timing of the moving-horizon estimator (issue 5): seconds per sample vs the 1 ms sample period.

Runs the protocol's L1 case (1 % noise, truth 49x25, estimator 25x13, 1 s at 1 ms = 1001 samples)
and reports, per backend, the start-up (first window, scan, coarse-to-fine), the moving windows,
the total for 1 s of data and the seconds per sample; the data-only lambda selection separately;
the effect of modal reduction; and the JEKF for reference. Target: 1 s of data in <= 1 s.

Usage::

    .venv/bin/python benchmarks/bench_mhe.py [--repeat 3] [--skip-jekf] [--json out.json]

The IPOPT backend is timed twice: as configured (the exact Hessian evaluated once per warm window
and held constant, cold start through damped Gauss–Newton steps) and as before issue 15 (the exact
Hessian at every IPOPT iterate, cold start included).

Timings are medians over ``--repeat`` runs on one thread per process (``OMP_NUM_THREADS=1`` is
set before numpy loads), wall clock or (``--cpu``) the process's CPU time; on a shared machine
wall time is inflated by the competing processes, so the load average is printed with them.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from wingopt.estimation.mhe import MHESettings, MovingHorizonEstimator  # noqa: E402
from wingopt.estimation.mhe.solvers import IpoptSolver  # noqa: E402
from wingopt.membrane import MembraneModel  # noqa: E402
from wingopt.problem import load_problem  # noqa: E402
from wingopt.workflows.protocols import simulate_case  # noqa: E402
from wingopt.workflows.studies import load_field  # noqa: E402

CLOCK = time.perf_counter
"""Wall clock by default; ``--cpu`` switches to this process's CPU time (a shared machine's load
inflates wall time by the number of competing processes; CPU time is what the estimator costs)."""


def timed_run(model, meas, settings, solver=None):
    """(setup s, run s, result, estimator); ``solver`` replaces the window solver of ``settings``."""
    t0 = CLOCK()
    est = MovingHorizonEstimator(model, settings)
    if solver is not None:
        est.solver = est._step_solver = solver
    est.setup(meas)
    t1 = CLOCK()
    res = est.run()
    t2 = CLOCK()
    return t1 - t0, t2 - t1, res, est


def median_runs(model, meas, settings, repeat, solver=None):
    runs = [timed_run(model, meas, settings, solver) for _ in range(repeat)]
    setup = float(np.median([r[0] for r in runs]))
    run = float(np.median([r[1] for r in runs]))
    return setup, run, runs[-1][2], runs[-1][3]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--skip-jekf", action="store_true")
    ap.add_argument("--json", help="write the numbers to this file")
    ap.add_argument("--cpu", action="store_true", help="report process CPU time instead of wall time")
    args = ap.parse_args()
    global CLOCK
    if args.cpu:
        CLOCK = time.process_time

    problem = load_problem("membrane")
    model = MembraneModel.from_problem(problem)
    case = simulate_case(problem, "L1", 0.01, 0)
    meas = dataclasses.replace(case.measurements, noise_std=None)
    n = meas.count
    clock = "process CPU time" if args.cpu else "wall time"
    print(
        f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; {n} samples at 1 ms; "
        f"25x13 estimator; {clock}, median of {args.repeat}"
    )

    # The data-only lambda once (numpy backend), then every backend at that lambda.
    setup, run, res, est = median_runs(model, meas, MHESettings(), args.repeat)
    lam = res.regularization
    out = {"samples": n, "lambda": lam, "rows": []}
    err = case.load_error(load_field(res, model))
    cols = f"{'start-up s':>10s} {'windows s':>10s} {'total s':>8s} {'s/sample':>9s} {'load err':>9s}"
    header = f"{'configuration':44s} {cols}"
    print(header)
    print("-" * len(header))

    def row(name, setup, run, res):
        total = setup + run
        e = case.load_error(load_field(res, model))
        print(f"{name:44s} {setup:10.3f} {run:10.3f} {total:8.3f} {total / n:9.2e} {e:9.4f}")
        out["rows"].append(
            {"name": name, "setup_s": setup, "run_s": run, "total_s": total, "s_per_sample": total / n, "load_error": e}
        )

    row("numpy, lambda from the data (path + rule)", setup, run, res)
    print(f"  (lambda = {lam:.3g}, chosen on the first window; {res.info['windows']} windows)")
    for name, s in [
        ("numpy (Newton/LM), fixed lambda", MHESettings(regularization=lam)),
        ("cvxpy + Clarabel (GN QPs), fixed lambda", MHESettings(regularization=lam, backend="cvxpy")),
        ("cvxpy + OSQP (GN QPs), fixed lambda", MHESettings(regularization=lam, backend="cvxpy", qp_solver="osqp")),
        ("casadi + IPOPT (NLP), fixed lambda", MHESettings(regularization=lam, backend="ipopt")),
    ]:
        # The first call of cvxpy/casadi compiles the problem: time the steady state.
        timed_run(model, meas, s)
        setup, run, r, _ = median_runs(model, meas, s, args.repeat)
        row(name, setup, run, r)
    # IPOPT before issue 15: the exact Hessian evaluated at every iterate, also from the cold start.
    s = MHESettings(regularization=lam, backend="ipopt")
    old = IpoptSolver(s.max_iterations, s.tolerance, hessian="analytic", cold_start_lm=False)
    timed_run(model, meas, s, old)
    setup, run, r, _ = median_runs(model, meas, s, args.repeat, old)
    row("  IPOPT, exact Hessian every iterate (before)", setup, run, r)

    print("\nmodal reduction (numpy, fixed lambda):")
    for modes in (20, 40, 60, 100, None):
        s = MHESettings(regularization=lam, modes=modes)
        setup, run, r, _ = median_runs(model, meas, s, 1 if modes is None else args.repeat)
        row(f"  {modes or 'all 325'} modes", setup, run, r)

    if not args.skip_jekf:
        from wingopt.estimation import jekf as jekf_presets
        from wingopt.estimation.jekf import JEKFSettings, jekf_identify

        print("\nJEKF (seed's filter, all modes, modal block structure):")
        t0 = CLOCK()
        r = jekf_identify(model, meas, JEKFSettings.tuned(1.78e-5))
        t1 = CLOCK()
        row("  JEKF, one run at fixed lambda", 0.0, t1 - t0, r)
        t0 = CLOCK()
        r = jekf_presets.identify(model, meas, variant="tuned", initial_load=200.0)
        t1 = CLOCK()
        row("  tuned JEKF incl. its data-only lambda search", 0.0, t1 - t0, r)
    print(f"\nreference: the sample period is 1.0e-03 s; first row's load error {err:.4f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)


if __name__ == "__main__":
    main()
