"""Latency and memory of the streaming estimators (issue 15): per-sample time against the period.

``--model linear`` (default):

Streams the protocol's L1 record (truth 49x25, estimator 25x13, 1 % noise, 1 s at 1 kHz) sample by
sample through :class:`~wingopt.estimation.streaming.StreamingEstimator`, then continues with
``--seconds`` of steady data (the record's final noise-free outputs plus noise of the same level:
the membrane is in equilibrium after ~1 s). ``--model nonlinear``: the same with the Berger truth
(:func:`~wingopt.workflows.protocols.simulate_case` with ``truth="berger"``: the full-order Berger
membrane on 49x25, 8 sub-steps, L1, 1 %; before the model-layer refactor a 120-mode modal Berger
truth) through :class:`~wingopt.estimation.streaming.nonlinear.NonlinearStreamingEstimator`, against
the batch realistic estimator (:func:`~wingopt.estimation.records.identify_record`, defaults).
``--model fvk``: the FvK truth (``simulate_case(..., truth="fvk")``, 49x25, 2 sub-steps, L1, 1 %)
through the FvK stream (``NonlinearStreamSettings(membrane_model="fvk")``, the ``--follow`` default),
against the batch FvK estimator.
Prints, in one run:

* p50 / p99 / max per-sample CPU time (``time.thread_time``) and wall time as fractions of the
  1 ms period, for the whole stream, the 1 s record, its tracking phase and the steady part;
* the one-off start-up (the batch ``setup`` on the buffered samples);
* the final lift against the batch MHE on the same 1 s record and against the truth;
* resident memory (VmRSS, /proc/self/status) at the end of the record and its largest growth over
  the steady part; the drift of the incrementally updated normal equations.

Usage::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 nice python benchmarks/bench_streaming.py --seconds 3600
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 nice python benchmarks/bench_streaming.py --model nonlinear --seconds 120
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 nice python benchmarks/bench_streaming.py --model fvk --seconds 600
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 nice python benchmarks/bench_streaming.py --seconds 1   # quickest

One thread, one process; on a shared machine the wall time includes preemption (the load average
is printed with the numbers).
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

from wingopt.estimation.mhe import mhe_identify  # noqa: E402
from wingopt.estimation.records import RecordSettings, identify_record  # noqa: E402
from wingopt.estimation.streaming import StreamingEstimator, StreamSettings  # noqa: E402
from wingopt.estimation.streaming.nonlinear import NonlinearStreamingEstimator, NonlinearStreamSettings  # noqa: E402
from wingopt.membrane import MembraneModel  # noqa: E402
from wingopt.problem import load_problem  # noqa: E402
from wingopt.workflows.protocols import simulate_case  # noqa: E402


def rss_mb() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def stats(x: np.ndarray, period: float) -> dict:
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return {}
    p50, p99 = np.percentile(x, [50, 99])
    return {"n": int(x.size), "p50": p50 / period, "p99": p99 / period, "max": float(x.max()) / period}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", choices=("linear", "nonlinear", "fvk"), default="linear", help="estimator and truth")
    ap.add_argument("--tracking-substeps", type=int, default=1, help="nonlinear: sub-steps per sample after start-up")
    ap.add_argument("--seconds", type=float, default=60.0, help="steady data streamed after the 1 s record")
    ap.add_argument("--load", default="L1")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--relinearize", type=int, default=4)
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("--progress", action="store_true", help="print RSS and latency every 60 s of stream")
    args = ap.parse_args()

    problem = load_problem("membrane")
    model = MembraneModel.from_problem(problem)
    nonlinear = args.model in ("nonlinear", "fvk")
    mm = "fvk" if args.model == "fvk" else "berger"
    if args.model == "fvk":
        case = simulate_case(problem, args.load, 0.01, args.seed, (49, 25), t_end=1.0, truth="fvk", substeps=2)
    elif nonlinear:
        case = simulate_case(problem, args.load, 0.01, args.seed, (49, 25), t_end=1.0, truth="berger", substeps=8)
    else:
        case = simulate_case(problem, args.load, 0.01, args.seed, (49, 25), t_end=1.0)
    meas = dataclasses.replace(case.measurements, noise_std=None)  # the estimators are not told the noise
    dt = float(meas.t[1] - meas.t[0])
    t0 = time.process_time()
    batch = identify_record(model, meas, RecordSettings(membrane_model=mm)) if nonlinear else mhe_identify(model, meas)
    batch_cpu = time.process_time() - t0

    if nonlinear:
        settings = NonlinearStreamSettings(tracking_substeps=args.tracking_substeps, membrane_model=mm)
        est = NonlinearStreamingEstimator(model, settings)
    else:
        est = StreamingEstimator(model, StreamSettings(relinearize=args.relinearize))
    K0 = meas.count
    K1 = int(round(args.seconds / dt))
    cpu = np.full(K0 + K1, np.nan)  # allocated and touched before the memory baseline
    wall = np.full(K0 + K1, np.nan)
    phase = np.zeros(K0 + K1, dtype=np.int8)
    codes = {"waiting": 0, "provisional": 1, "startup": 2, "tracking": 3}
    for k in range(K0):
        c, w = time.thread_time(), time.perf_counter()
        e = est.push(meas.t[k], meas.values[k])
        cpu[k], wall[k] = time.thread_time() - c, time.perf_counter() - w
        phase[k] = codes[e.phase]
    record = {"lift": e.lift, "lift_std": e.lift_std, "chi2_per_datum": e.chi2_per_datum, "adequate": e.adequate}
    rss0 = rss_mb()
    rss_max, rss_trace = rss0, []
    clean = case.trajectory.outputs[-1]
    sigma = np.std(meas.values[-400:] - case.trajectory.outputs[-400:], axis=0)
    rng = np.random.default_rng(1000 + args.seed)
    chunk = 1000
    t_steady = time.perf_counter()
    for start in range(0, K1, chunk):
        n = min(chunk, K1 - start)
        Y = clean + sigma * rng.standard_normal((n, clean.size))
        for j in range(n):
            k = K0 + start + j
            c, w = time.thread_time(), time.perf_counter()
            e = est.push(meas.t[0] + k * dt, Y[j])
            cpu[k], wall[k] = time.thread_time() - c, time.perf_counter() - w
        phase[K0 + start : K0 + start + n] = 3
        if (start // chunk) % 60 == 0 or start + n == K1:
            r = rss_mb()
            rss_max = max(rss_max, r)
            rss_trace.append((round((K0 + start + n) * dt, 1), round(r, 2)))
            if args.progress:  # the last minute of stream: RSS and CPU per sample (of the period)
                last = cpu[max(K0, K0 + start + n - 60000) : K0 + start + n]
                p50, p99 = np.percentile(last, [50, 99]) / dt
                now = (K0 + start + n) * dt
                print(f"t = {now:8.0f} s  RSS {r:8.2f} MB  cpu p50 {p50:.3f} p99 {p99:.3f}", flush=True)
    steady_wall = time.perf_counter() - t_steady
    info = est.info()
    trk = phase[:K0] == 3
    out = {
        "model": args.model,
        "tracking_substeps": args.tracking_substeps if nonlinear else None,
        "load_average": os.getloadavg(),
        "streamed_s": (K0 + K1) * dt,
        "samples": K0 + K1,
        "period_s": dt,
        "cpu_all": stats(cpu, dt),
        "wall_all": stats(wall, dt),
        "cpu_record": stats(cpu[:K0], dt),
        "wall_record": stats(wall[:K0], dt),
        "cpu_record_tracking": stats(cpu[:K0][trk], dt),
        "wall_record_tracking": stats(wall[:K0][trk], dt),
        "cpu_provisional": stats(cpu[:K0][phase[:K0] == 1], dt),
        "cpu_steady": stats(cpu[K0:], dt),
        "wall_steady": stats(wall[K0:], dt),
        "steady_wall_s": steady_wall,
        "startup_cpu_s": info["startup_cpu_s"],
        "startup_wall_s": info["startup_wall_s"],
        "batch_cpu_s": batch_cpu,
        "lift_record_stream": record["lift"],
        "lift_record_batch": float(batch.lift[-1]),
        "lift_record_rel_diff": abs(record["lift"] / batch.lift[-1] - 1.0),
        "lift_std_record_stream": record["lift_std"],
        "lift_std_record_batch": float(batch.lift_std[-1]),
        "true_lift": float(case.lift_history[-1]) if nonlinear else case.true_lift,
        "lift_final": e.lift,
        "lift_std_final": e.lift_std,
        "chi2_per_datum_final": e.chi2_per_datum,
        "adequate_final": e.adequate,
        "rss_mb_after_record": rss0,
        "rss_growth_mb": rss_max - rss0,
        "rss_trace": rss_trace,
    }
    if nonlinear:
        out.update(est.parameters(), batch_parameters=batch.info["parameters"])
    else:
        out.update(
            normal_equations_drift=info["normal_equations_drift"], active_unknowns_final=int(est._core.active.size)
        )
    for key in ("cpu_all", "wall_all", "cpu_record", "cpu_record_tracking", "wall_record_tracking",
                "cpu_provisional", "cpu_steady", "wall_steady"):  # fmt: skip
        s = out[key]
        if s:
            line = f"{key:22s} n={s['n']:8d}  p50 {s['p50']:.3f}  p99 {s['p99']:.3f}  max {s['max']:.3f}"
            print(line + "  (of the period)")
    for key in ("startup_cpu_s", "startup_wall_s", "batch_cpu_s", "lift_record_stream", "lift_record_batch",
                "lift_record_rel_diff", "true_lift", "lift_final", "lift_std_final", "chi2_per_datum_final",
                "rss_mb_after_record", "rss_growth_mb", "normal_equations_drift", "steady_wall_s",
                "load_average", "parameters", "parameters_std", "batch_parameters"):  # fmt: skip
        if key in out:
            print(f"{key:22s} {out[key]}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1, default=float)


if __name__ == "__main__":
    main()
