"""Latency of the morphing controller step against its sample period, for every QP backend (issue 15).

For each backend: the whole closed-loop controller step on the full-order plant (Kalman filter
update, QP data from the estimate, solve, filter prediction), 2 s of the chosen shape at the
chosen period, timed per step by wall clock (``perf_counter``) and by this thread's CPU time
(``thread_time``: what the step costs, without the preemption of a shared machine), printed as
p50 / p99 / max fractions of the period. Then agreement on the *same* QPs: the parameters
``p = (x_hat, w_prev)`` met by the first backend's loop are re-solved by every backend, and the
objective (relative to the first backend's: negative only where a backend bends a bound), the
largest bound violation (V) and the first input's distance to the first backend's (V) are
printed: a "solved" status is not enough. (The condensed QP is ill-conditioned: inputs that differ
by a volt can cost the same to 1e-8.)

Usage::

    OMP_NUM_THREADS=1 nice python benchmarks/bench_latency.py                  # 13x61, twist, 10 ms
    OMP_NUM_THREADS=1 nice python benchmarks/bench_latency.py --period 0.001 --max-modes 150 --backends daqp,clarabel
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from wingopt.control.closed_loop import make_plant  # noqa: E402
from wingopt.control.mpc import make_qp_controller  # noqa: E402
from wingopt.optim.registry import available_backends  # noqa: E402
from wingopt.plate import PlateModel  # noqa: E402
from wingopt.problem import load_problem, parse_mesh  # noqa: E402

VMIN, VMAX = -500.0, 1500.0
CONFIGS = {
    "daqp": dict(solver="daqp"),
    "clarabel": dict(solver="clarabel"),
    "osqp": dict(solver="osqp"),
    "piqp": dict(solver="piqp"),
    "piqp (sparse)": dict(solver="piqp", formulation="sparse"),
    "proxqp": dict(solver="proxqp"),
    "casadi-qp/qpoases": dict(solver="casadi-qp", plugin="qpoases"),
    "ipopt": dict(solver="ipopt"),
}


def run_loop(model, plant, ctrl, target, steps: int, record: bool):
    """Closed loop from rest; per-step wall and CPU seconds, final shape error, the QP parameters met."""
    ctrl.reset(model, target)
    params = []
    if record:
        solve = ctrl.backend.solve

        def recording(p, warm=None):
            params.append(np.array(p))
            return solve(p, warm)

        ctrl.backend.solve = recording
    x = plant.initial_state(np.zeros(model.n), np.zeros(model.n))
    C = model.sensing
    wall, cpu = np.empty(steps), np.empty(steps)
    for k in range(steps):
        z, _ = plant.fields(x)
        y = C @ z
        t0, c0 = time.perf_counter(), time.thread_time()
        u = ctrl.step(y)
        cpu[k], wall[k] = time.thread_time() - c0, time.perf_counter() - t0
        x = plant.step(x, np.clip(u, VMIN, VMAX))
    z, _ = plant.fields(x)
    err = model.m_norm(z - target) / model.m_norm(target)
    if record:
        del ctrl.backend.solve
    return wall, cpu, float(err), params


def frac(t, period):
    return [np.percentile(t, 50) / period, np.percentile(t, 99) / period, t.max() / period]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--mesh", default="13x61")
    ap.add_argument("--shape", default="twist")
    ap.add_argument("--period", type=float, default=0.01)
    ap.add_argument("--t-end", type=float, default=2.0)
    ap.add_argument("--horizon", type=int, default=None)
    ap.add_argument("--max-modes", type=int, default=None, help="most modes of the reduction (1 kHz needs > 60)")
    ap.add_argument("--backends", default=",".join(CONFIGS), help=f"comma list of {', '.join(CONFIGS)}")
    args = ap.parse_args()
    installed = set(available_backends())
    labels = [b for b in args.backends.split(",") if CONFIGS[b]["solver"] in installed]
    skipped = [b for b in args.backends.split(",") if b not in labels]

    model = PlateModel.from_problem(load_problem("plate"), parse_mesh(args.mesh))
    target = model.target(args.shape)
    plant = make_plant(model, args.period)
    steps = int(round(args.t_end / args.period))
    print(
        f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}, "
        f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores, one BLAS thread"
    )
    print(
        f"mesh {args.mesh} ({model.n} dofs), {args.shape}, period {args.period * 1e3:g} ms, {steps} steps, "
        f"limits {VMIN:g}..{VMAX:g} V" + (f"; not installed: {', '.join(skipped)}" if skipped else "")
    )
    ctrls, rows, ref_params = {}, [], None
    for label in labels:
        opts = dict(CONFIGS[label])
        if args.horizon:
            opts["horizon"] = args.horizon
        if args.max_modes:
            opts["max_modes"] = args.max_modes
        ctrl = make_qp_controller(model, target, vmin=VMIN, vmax=VMAX, period=args.period, **opts)
        ctrls[label] = ctrl
        wall, cpu, err, params = run_loop(model, plant, ctrl, target, steps, record=ref_params is None)
        ref_params = ref_params or params
        rows.append((label, ctrl, wall, cpu, err))
    info = rows[0][1].info
    print(f"reduced model {info['reduced_modes']} modes, {info['reduced_states']} states; horizon {info['qp_horizon']}")
    head = (
        f"{'backend':18s} {'form':9s} {'vars':>5s} {'wall p50':>8s} {'p99':>6s} {'max':>6s} "
        f"{'CPU p50':>8s} {'p99':>6s} {'max':>6s} {'iters':>5s} {'shape err':>9s}"
    )
    print("\nper-step time / period (whole controller step)\n" + head + "\n" + "-" * len(head))
    for label, ctrl, wall, cpu, err in rows:
        w, c = frac(wall, args.period), frac(cpu, args.period)
        print(
            f"{label:18s} {ctrl.info['qp_formulation']:9s} {ctrl.qp.n_variables:5d} {w[0]:8.4f} {w[1]:6.4f} "
            f"{w[2]:6.4f} {c[0]:8.4f} {c[1]:6.4f} {c[2]:6.4f} {np.median(ctrl.iterations):5.0f} {err:9.5f}"
        )

    # Agreement on the same QPs: the parameters the first backend's loop met, re-solved by all.
    m = rows[0][1].problem.m
    obj = {label: [] for label in labels}
    viol = {label: [] for label in labels}
    first = {label: [] for label in labels}
    for p in ref_params:
        for label in labels:
            ctrl = ctrls[label]
            sol = ctrl.backend.solve(p)
            obj[label].append(sol.objective)
            viol[label].append(ctrl.qp.violation(sol.v, p) * 1e3)  # kV -> V
            first[label].append(sol.v[:m] * 1e3)
    ref_obj = np.asarray(obj[labels[0]])
    scale = np.maximum(np.abs(ref_obj), 1e-12)
    ref = np.asarray(first[labels[0]])
    head = (
        f"{'backend':18s} {'obj - ref (rel) min':>19s} {'max':>9s} {'max bound viol V':>16s} {'max |u0 - ref| V':>16s}"
    )
    print(
        f"\nagreement on the {len(ref_params)} QPs met by the {labels[0]} loop (reference {labels[0]})\n"
        + head
        + "\n"
        + "-" * len(head)
    )
    for label in labels:
        d_obj = (np.asarray(obj[label]) - ref_obj) / scale
        d_u = float(np.max(np.abs(np.asarray(first[label]) - ref)))
        print(f"{label:18s} {d_obj.min():19.2e} {d_obj.max():9.2e} {max(viol[label]):16.2e} {d_u:16.3e}")


if __name__ == "__main__":
    main()
