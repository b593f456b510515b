"""Speed of the default estimator on the tunnel stand-in, one core: the steady route against the
transient route the package took before (issue 23: 1.5 s of 300 Hz four-sensor data in <= 1 s CPU).

For the first ``--seconds`` of ``examples/data/tunnel_300Hz.csv`` (default 1.5 s: 450 samples)
and for the whole record (4.6 s), it times, in one run and on the same estimator object:

* ``steady`` - the default path (``record = "auto"`` routes a record without a transient here),
  once cold (the first call of a process: the static FvK operators and the modal model are built)
  and best-of-``--repeat`` warm;
* ``steady, aerodynamic prior`` - the same with the flow declared (``pressure_prior =
  "aerodynamic"``, ``leading_edge = "x0"``);
* ``transient`` - the route the default took on such records before (``record = "transient"``),
  once (it is slow: 60-140 s), unless ``--no-transient``.

CPU time is ``time.process_time`` (insensitive to other processes on a shared machine). Prints the
times, lifts against the header's truth, the ratios, and exits 1 if the warm default exceeds the
budget (``--budget``, CPU seconds per ``--seconds`` of data)::

    OPENBLAS_NUM_THREADS=1 nice python benchmarks/bench_tunnel.py [--repeat 3] [--no-transient]
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from wingopt.estimation.records import RecordSettings, identify_record  # noqa: E402
from wingopt.measurements import Measurements, read_measurements  # noqa: E402
from wingopt.membrane import MembraneModel  # noqa: E402
from wingopt.problem import load_problem  # noqa: E402

RECORD = Path(__file__).resolve().parents[1] / "examples" / "data" / "tunnel_300Hz.csv"


def _cpu(fn):
    c0 = time.process_time()
    out = fn()
    return time.process_time() - c0, out


def _truth() -> float:
    return float(re.search(r"true mean lift ([0-9.]+) N", RECORD.read_text()).group(1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=1.5, help="the record's first S seconds (default 1.5)")
    ap.add_argument("--repeat", type=int, default=3, help="warm runs, best of (default 3)")
    ap.add_argument("--budget", type=float, default=1.0, help="CPU s allowed for --seconds of data (default 1)")
    ap.add_argument("--no-transient", action="store_true", help="skip the slow transient route")
    args = ap.parse_args(argv)
    problem = load_problem("membrane")
    full, _ = read_measurements(RECORD, problem.sensor_names)
    n = int(np.searchsorted(full.t - full.t[0], args.seconds - 1e-9)) + 1
    part = Measurements(full.t[:n], full.values[:n], full.sensor_names, None, "bench")
    truth = _truth()
    aero = problem.with_identification(pressure_prior="aerodynamic", leading_edge="x0")
    steady = RecordSettings(membrane_model="fvk")
    rows = []

    def run(label, prob, meas, settings, repeat):
        model = MembraneModel.from_problem(prob)
        times = []
        for _ in range(repeat):
            cpu, res = _cpu(lambda: identify_record(model, meas, settings))
            times.append(cpu)
        lift, std = res.reported_lift
        rows.append((label, meas.count, times[0], min(times[1:] or times), lift, std))
        print(f"{label:34s} {meas.count:5d} samples  first {times[0]:6.2f} s  warm {rows[-1][3]:6.2f} s CPU  "
              f"lift {lift:.4f} +- {std:.4f} N ({100 * (lift / truth - 1):+.1f} %)", flush=True)  # fmt: skip
        return rows[-1]

    print(f"{RECORD.name}: true mean lift {truth:.4f} N (SYNTHETIC stand-in); one core, CPU seconds")
    default = run("steady (default)", problem, part, steady, 1 + args.repeat)
    run("steady, aerodynamic prior", aero, part, steady, 1 + args.repeat)
    run("steady (default), whole record", problem, full, steady, 1 + args.repeat)
    if not args.no_transient:
        old = run("transient route (before)", problem, part, RecordSettings(membrane_model="fvk",
                  record="transient"), 1)  # fmt: skip
        print(f"ratio transient / steady (warm), {part.count} samples: {old[2] / default[3]:.0f}x")
    per = default[3] / args.seconds
    print(f"default: {default[3]:.2f} s CPU for {args.seconds:g} s of data ({per:.2f} s per s; budget "
          f"{args.budget:g} s for {args.seconds:g} s)")  # fmt: skip
    return 0 if default[3] <= args.budget else 1


if __name__ == "__main__":
    sys.exit(main())
