"""Transient records through an analog anti-aliasing filter: point-sampled, filter undeclared, declared.

L1 on FvK truth (``benchmarks/fuzz_records.py``'s generator: 37x19 full order, prestrains x1.1 and
x0.9 of the file's, 1 % noise, 1 s at 300 Hz), handed over by a 4th-order Butterworth at fs/3 (the
filter run at 4x the record's rate and settled on the wing's first state), released from the bubble
(declared) or loaded from rest. One row per record and acquisition (docs/lab_records.md)::

    python benchmarks/daq_transient.py [--cases 2] [--warnings]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import fuzz_records as fz  # noqa: E402 - the fuzz's generator, beside this file

import wingopt as wo  # noqa: E402
from wingopt.measurements.acquisition import Acquisition  # noqa: E402

CASES = [("L1", "bubble", 300, 1), ("L1", "rest", 300, 2), ("L3", "bubble", 500, 3), ("LE", "rest", 300, 4)]


def case(load: str, start: str, rate: int, seed: int) -> dict:
    return {
        "index": -1,
        "route": "batch",
        "load": load,
        "prestrain_factor": [1.1, 0.9],
        "damping": 1.0,
        "noise_percent": 1.0,
        "t_end": 1.0,
        "rate_hz": rate,
        "gust": False,
        "start": start,
        "declared_shape": start == "bubble",
        "daq": "butter-fs/3",
        "rounded_stamps": False,
        "seed": seed,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=2, help="how many of the four records")
    ap.add_argument("--warnings", action="store_true", help="print each run's warnings")
    args = ap.parse_args(argv)
    for load, start, rate, seed in CASES[: args.cases]:
        c = case(load, start, rate, seed)
        problem = wo.load_problem("membrane").with_identification(initial_deflection=0.01 if start == "bubble" else 0.0)
        rec, _, truth = fz.simulate(c, problem)
        problem = problem.with_identification(initial_load=truth["side"] * abs(problem.identification.initial_load))
        for acquisition in ("point-sampled", "undeclared", "declared"):
            c["daq"] = "point" if acquisition == "point-sampled" else "butter-fs/3"
            meas = fz._measurements(c, rec, truth["oversample"], problem.sensor_names)
            declared = Acquisition("butterworth", order=4, cutoff_hz=rate / 3)
            p = dataclasses.replace(problem, acquisition=declared) if acquisition == "declared" else problem
            t0 = time.process_time()
            run = wo.identify(p, data=meas)
            lift, band = run.result.reported_lift
            chi2 = run.result.info.get("adequacy", {}).get("chi2_per_datum", float("nan"))
            true = truth["lift"]
            print(
                f"{load} from {start}, {rate} Hz, {acquisition}: {lift:.4f} ± {band:.4f} N for {true:.4f} "
                f"({100 * (lift / true - 1):+.1f} %, {(lift - true) / band:+.2f} bands), chi-square {chi2:.2f}, "
                f"{run.status}, {len(run.warnings)} warnings ({time.process_time() - t0:.1f} s CPU)",
                flush=True,
            )
            for w in run.warnings if args.warnings else ():
                print("    ", w)
    return 0


if __name__ == "__main__":
    sys.exit(main())
