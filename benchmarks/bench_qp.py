"""Timing of the morphing QP (issue 4): real time at 100 Hz on 13x61?

Prints, for the chosen mesh (default 13x61) and shape(s):

* the reduced model's size (modes kept by the tolerance, states, measured error and band);
* build time (reduction, static optimum, terminal cost, QP assembly, backend compile) against the
  re-solve time of one closed-loop step;
* the median (and 90th percentile, max) time per closed-loop QP solve, relative to the 10 ms
  control period (target: below 1.0), for each backend, measured inside the closed-loop harness
  on the full-order plant (the controller's own solve times; ``step`` adds the Kalman filter).

Usage::

    OMP_NUM_THREADS=1 python benchmarks/bench_qp.py                   # 13x61, twist, all backends
    OMP_NUM_THREADS=1 python benchmarks/bench_qp.py --mesh 7x31 --shape all --backends clarabel

For the whole controller step against the period (wall and CPU time, p50/p99/max) and the
agreement of all backends on the same QPs, see ``benchmarks/bench_latency.py``.

Single-threaded BLAS is the honest setting on this loaded 2-core machine (threaded BLAS on tiny
matrices only adds contention).
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

from wingopt.control.closed_loop import simulate_closed_loop
from wingopt.control.mpc import make_qp_controller
from wingopt.control.plant import make_plant
from wingopt.plate import PlateModel
from wingopt.problem import load_problem, parse_mesh

PERIOD = 0.01
CONFIGS = {
    "daqp": dict(solver="daqp"),
    "clarabel": dict(solver="clarabel"),
    "osqp": dict(solver="osqp"),
    "osqp (tol 1e-5)": dict(solver="osqp", tolerance=1e-5),
    "casadi-qp/qpoases": dict(solver="casadi-qp", plugin="qpoases"),
    "casadi-qp/piqp": dict(solver="casadi-qp", plugin="piqp"),
    "piqp": dict(solver="piqp"),
    "proxqp": dict(solver="proxqp"),
    "ipopt": dict(solver="ipopt"),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--mesh", default="13x61")
    ap.add_argument("--shape", default="twist", help="twist, camber, bending or all")
    ap.add_argument("--backends", default=",".join(CONFIGS), help=f"comma list of {', '.join(CONFIGS)}")
    ap.add_argument("--horizon", type=int, default=None, help="steps (default: the controller's, 10)")
    ap.add_argument("--t-end", type=float, default=2.0)
    args = ap.parse_args()

    problem = load_problem("plate")
    t0 = time.perf_counter()
    model = PlateModel.from_problem(problem, parse_mesh(args.mesh))
    t_model = time.perf_counter() - t0
    t0 = time.perf_counter()
    plant = make_plant(model, PERIOD)
    t_plant = time.perf_counter() - t0
    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}")
    print(f"mesh {args.mesh}: {model.n} dofs; model {t_model:.2f} s; plant ({plant.description}) {t_plant:.2f} s")
    shapes = ("twist", "camber", "bending") if args.shape == "all" else (args.shape,)
    rows = []
    for shape in shapes:
        target = model.target(shape)
        for label in args.backends.split(","):
            opts = dict(CONFIGS[label])
            if args.horizon:
                opts["horizon"] = args.horizon
            t0 = time.perf_counter()
            ctrl = make_qp_controller(model, target, vmin=-500.0, vmax=1500.0, period=PERIOD, **opts)
            build = time.perf_counter() - t0
            cl = simulate_closed_loop(model, ctrl, target, t_end=args.t_end, vmin=-500.0, vmax=1500.0)
            s = ctrl.summary()
            solve = np.asarray(ctrl.solve_times)
            step = cl.step_seconds
            rows.append((shape, label, s, build, solve, step, cl.final_shape_error))
    first = rows[0][2]
    print(
        f"reduced model: {first['reduced_modes']} modes + quasi-static residual of 9 patches -> "
        f"{first['reduced_states']} states (frequency-response error {first['reduction_error']:.2e} "
        f"on 0..{first['reduction_band_hz']:g} Hz); QP: horizon {first['qp_horizon']}, "
        f"{first['qp_variables']} variables ({first['qp_formulation']} form for {rows[0][1]})"
    )
    print()
    head = (
        f"{'shape':8s} {'backend':18s} {'form':9s} {'build s':>8s} {'solve med ms':>12s} {'p90':>6s} "
        f"{'max':>6s} {'med/10ms':>8s} {'step med/10ms':>13s} {'iters':>5s} {'err':>7s} {'static':>7s}"
    )
    print(head)
    print("-" * len(head))
    for shape, label, s, build, solve, step, err in rows:
        print(
            f"{shape:8s} {label:18s} {s['qp_formulation']:9s} {build:8.3f} {np.median(solve) * 1e3:12.2f} "
            f"{np.percentile(solve, 90) * 1e3:6.1f} {solve.max() * 1e3:6.1f} {np.median(solve) / PERIOD:8.3f} "
            f"{np.median(step) / PERIOD:13.3f} {s['qp_iterations_median']:5.0f} {err:7.4f} "
            f"{s['static_optimum_error']:7.4f}"
        )
    print()
    for shape, label, s, build, solve, _, _ in rows[:1] + [r for r in rows[1:] if r[1] == "clarabel"]:
        b = s["build_s"]
        print(
            f"build vs re-solve ({shape}, {label}): build {build:.3f} s = reduction {b['reduction_s']:.3f} + "
            f"static optimum {b['static_s']:.3f} + terminal Riccati {b['terminal_s']:.3f} + assembly "
            f"{b['assemble_s']:.3f} + backend compile {b['backend_s']:.3f} (+ filter); re-solve median "
            f"{np.median(solve) * 1e3:.2f} ms -> build = {build / np.median(solve):.0f} re-solves"
        )


if __name__ == "__main__":
    main()
