"""The nonlinear stream through an analog anti-aliasing filter: point-sampled, filter undeclared, declared.

The records of ``benchmarks/daq_transient.py`` (``benchmarks/fuzz_records.py``'s generator: FvK
truth 37x19 full order, prestrains x1.1 and x0.9 of the file's, 1 % noise, 1 s at 300 Hz, a
4th-order Butterworth at fs/3 run at 4x the record's rate and settled on the wing's first state),
streamed by the default stream (``wingopt.workflows.stream.follow``, the FvK EKF, as the fuzz
does). One row per record and acquisition: the final lift and band, the truth, ``(lift - truth) /
band``, the status, the chi-square per datum (the start-up fit's, the last window's and the mean
of the tracking windows') and the samples reached::

    python benchmarks/stream_daq.py [--cases 3] [--seconds 1.0] [--daq delta-sigma-late]

``--gust``: a gust after the release (``fuzz_records``'s: 30 % for 0.2 s, starting at 0.3-0.6 of the
record), and each row's lift history against the truth's (RMS over the tracking samples, relative to
the final lift). ``--daq delta-sigma-late``: the fuzz's 65-tap converter FIR at 0.45 fs instead, its group delay
(8 samples) kept in the time stamps, declared as ``Acquisition("delta-sigma", delay_s=8 / rate)``.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import logging
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

import daq_transient  # noqa: E402 - the DAQ records' cases, beside this file
import fuzz_records as fz  # noqa: E402 - the fuzz's generator, beside this file

import wingopt as wo  # noqa: E402
from wingopt.measurements.acquisition import Acquisition  # noqa: E402
from wingopt.workflows.stream import follow  # noqa: E402

CASES = [("L1", "rest", 300, 2), ("L1", "bubble", 300, 1), ("L3", "bubble", 300, 3)]
ACQUISITIONS = ("point-sampled", "undeclared", "declared")


def case(load: str, start: str, rate: int, seed: int, seconds: float) -> dict:
    """A record of the stream route, handed over by the Butterworth (``daq_transient``'s, its truth
    oversampled 4x)."""
    return daq_transient.case(load, start, rate, seed) | {"route": "stream", "t_end": seconds}


def stream(problem, meas) -> tuple[dict, float, np.ndarray]:
    """The summary of ``follow`` on ``meas`` written as a CSV, the tracking windows' mean chi-square,
    and the tracking samples' ``(t, lift)`` ``(2, n)``."""
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "rec.csv"
        rows = np.column_stack([meas.t, meas.values])
        np.savetxt(src, rows, delimiter=",", header="t," + ",".join(meas.sensor_names), comments="")
        s = follow(problem, Path(tmp) / "out", source=str(src), idle_timeout=0.2)
        with open(Path(tmp) / "out" / "lift.csv", newline="") as fh:
            tracking = [r for r in csv.DictReader(fh) if r.get("phase") == "tracking" and r["lift_N"]]
    chi = [float(r["chi2_per_datum"]) for r in tracking]
    history = np.array([[float(r["t"]), float(r["lift_N"])] for r in tracking]).reshape(-1, 2).T
    return s, float(np.mean(chi)) if chi else float("nan"), history


def history_rms(history: np.ndarray, rec) -> float:
    """RMS of the tracking samples' lift against the truth's lift history, relative to its final value."""
    t, lift = history
    truth = np.interp(t, rec.measurements.t, rec.lift_history)
    return float(np.sqrt(np.mean((lift - truth) ** 2)) / abs(rec.lift_history[-1])) if t.size else float("nan")


def row(label: str, s: dict, mean_chi2: float, truth: float, count: int, cpu: float) -> str:
    lift, band = s.get("lift_N"), s.get("lift_std_N")
    est = s.get("estimator", {})
    if lift is None or not band:
        return f"{label}: no answer ({s.get('status')})"
    return (
        f"{label}: {lift:.4f} ± {band:.4f} N for {truth:.4f} ({100 * (lift / truth - 1):+.2f} %, "
        f"{(lift - truth) / band:+.2f} bands), {s.get('status')}, chi2/datum start-up "
        f"{est.get('startup_chi2_per_datum', float('nan')):.2f} "
        f"last window {s.get('chi2_per_datum', float('nan')):.2f} "
        f"tracking mean {mean_chi2:.2f}, {s.get('samples')}/{count} samples, {len(s.get('warnings', []))} warnings, "
        f"modelled: {est.get('acquisition')} ({cpu:.0f} s CPU)"
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=len(CASES), help="how many of the records")
    ap.add_argument("--seconds", type=float, default=1.0, help="each record's length (s)")
    ap.add_argument("--warnings", action="store_true", help="print each run's warnings")
    ap.add_argument("--daq", choices=("butterworth", "delta-sigma-late"), default="butterworth", help="the DAQ")
    ap.add_argument("--gust", action="store_true", help="a gust after the release (as the fuzz's); use --seconds 1.5")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    for load, start, rate, seed in CASES[: args.cases]:
        c = case(load, start, rate, seed, args.seconds) | {"gust": args.gust}
        problem = wo.load_problem("membrane").with_identification(initial_deflection=0.01 if start == "bubble" else 0.0)
        rec, _, truth = fz.simulate(c, problem)
        problem = problem.with_identification(initial_load=truth["side"] * abs(problem.identification.initial_load))
        late = args.daq == "delta-sigma-late"
        declared = (
            Acquisition("delta-sigma", delay_s=8.0 / rate)
            if late
            else Acquisition("butterworth", order=4, cutoff_hz=rate / 3)
        )
        for acquisition in ACQUISITIONS:
            c["daq"] = "point" if acquisition == "point-sampled" else "fir-0.45" if late else "butter-fs/3"
            meas = fz._measurements(c, rec, truth["oversample"], problem.sensor_names)
            p = dataclasses.replace(problem, acquisition=declared) if acquisition == "declared" else problem
            t0 = time.process_time()
            s, mean_chi2, history = stream(p, meas)
            label = f"{load} from {start}, {rate} Hz, {acquisition}"
            line = row(label, s, mean_chi2, truth["lift"], meas.count, time.process_time() - t0)
            print(line + f"; lift history RMS {100 * history_rms(history, rec):.0f} %" * args.gust, flush=True)
            for w in s.get("warnings", []) if args.warnings else ():
                print("    ", w)
    return 0


if __name__ == "__main__":
    sys.exit(main())
