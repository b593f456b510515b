"""Transient records through a DAQ's anti-aliasing filter: point-sampled, filter undeclared, declared.

L1 on FvK truth (``benchmarks/fuzz_records.py``'s generator: 37x19 full order, prestrains x1.1 and
x0.9 of the file's, 1 % noise, 1 s at 300 Hz), handed over by a 4th-order Butterworth at fs/3 (the
filter run at 4x the record's rate and settled on the wing's first state), released from the bubble
(declared) or loaded from rest. One row per record and acquisition (docs/lab_records.md), with the
chi-square per datum of the fit's first ``--head`` samples (the release)::

    python benchmarks/daq_transient.py [--cases 2] [--warnings] [--only declared] [--daq delta-sigma]

The declared rows' fits run the analog filter causally on the outputs' interpolant at the
integrator's sub-steps (:class:`~wingopt.measurements.analog_filter.CausalFilter`, what
``core.start.record_filter`` hands over), and the start-up's amplitude scan ranks its candidates by
their filtered outputs. ``--analog-truth`` filters the truth with the analog filter itself
(``scipy.signal.lsim`` on the 4x record, settled on its first value) instead of the fuzz's digital
design at 4x the rate (bilinear: 3 sigma off the analog filter at the release, chi-square 1.3-2.8
per datum over the first 10 samples, 0.01-0.03 after).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import fuzz_records as fz  # noqa: E402 - the fuzz's generator, beside this file
import numpy as np  # noqa: E402
from scipy import signal  # noqa: E402

import wingopt as wo  # noqa: E402
from wingopt.estimation.transient import estimator  # noqa: E402
from wingopt.estimation.transient.fit_result import residual_matrix  # noqa: E402
from wingopt.measurements.acquisition import Acquisition  # noqa: E402
from wingopt.measurements.series import Measurements  # noqa: E402

_LAST = {}
"""The last result's record problem and fit (``--head``)."""


def _record_result(real):
    def wrapped(rp, fit, *args, **kwargs):
        _LAST["rp"], _LAST["fit"] = rp, fit
        return real(rp, fit, *args, **kwargs)

    return wrapped


def _analog_measurements(c, rec, oversample, names, acquisition):
    """The truth record through the analog filter itself, decimated (``--analog-truth``)."""
    t, y = rec.measurements.t, rec.measurements.values
    A, B, C, D = acquisition.state_space()
    rest = -np.linalg.solve(A, B)
    sys_ = (A, B[:, None], C[None], D)
    out = np.stack([signal.lsim(sys_, y[:, i], t - t[0], X0=rest * y[0, i])[1] for i in range(y.shape[1])], 1)
    return Measurements(t[::oversample], out[::oversample], names, None, "analog truth")


DAQS = {"butterworth": "butter-fs/3", "delta-sigma": "fir-0.45", "delta-sigma-late": "fir-0.45"}
"""``--daq``: a 4th-order Butterworth at fs/3; the fuzz's 65-tap converter FIR at 0.45 fs with its
group delay (8 samples) compensated, as most drivers do; the same with the delay kept in the stamps
(declared as ``delay_s``)."""


def _declared(daq: str, rate: float) -> Acquisition:
    if daq == "butterworth":
        return Acquisition("butterworth", order=4, cutoff_hz=rate / 3)
    return Acquisition("delta-sigma", delay_s=8.0 / rate if daq == "delta-sigma-late" else None)


def _compensated_measurements(rec, oversample, names) -> Measurements:
    """The truth through the fuzz's converter FIR with its group delay taken out (``--daq delta-sigma``)."""
    t, y = rec.measurements.t, rec.measurements.values
    fs = 1.0 / (t[1] - t[0])  # the oversampled rate, as fuzz_records._acquire
    taps = signal.firwin(16 * oversample + 1, 0.45 * fs / oversample, fs=fs)
    lag = 8 * oversample
    padded = np.vstack([y, np.repeat(y[-1:], lag, axis=0)])
    out = signal.lfilter(taps, 1.0, padded, axis=0, zi=signal.lfilter_zi(taps, 1.0)[:, None] * y[0])[0][lag:]
    return Measurements(t[::oversample], out[::oversample], names, None, "delay-compensated converter")


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
    ap.add_argument("--only", choices=("point-sampled", "undeclared", "declared"), help="one acquisition's rows")
    ap.add_argument("--analog-truth", action="store_true", help="the truth through the analog filter (lsim)")
    ap.add_argument("--head", type=int, default=10, help="samples of the release whose chi-square is printed")
    ap.add_argument("--daq", choices=tuple(DAQS), default="butterworth", help="the DAQ that hands the record over")
    args = ap.parse_args(argv)
    estimator.fit_result = _record_result(estimator.fit_result)
    for load, start, rate, seed in CASES[: args.cases]:
        c = case(load, start, rate, seed)
        problem = wo.load_problem("membrane").with_identification(initial_deflection=0.01 if start == "bubble" else 0.0)
        rec, _, truth = fz.simulate(c, problem)
        problem = problem.with_identification(initial_load=truth["side"] * abs(problem.identification.initial_load))
        for acquisition in ("point-sampled", "undeclared", "declared"):
            if args.only not in (None, acquisition):
                continue
            c["daq"] = "point" if acquisition == "point-sampled" else DAQS[args.daq]
            declared = _declared(args.daq, rate)
            if args.daq == "delta-sigma" and acquisition != "point-sampled":
                meas = _compensated_measurements(rec, truth["oversample"], problem.sensor_names)
            elif args.analog_truth and acquisition != "point-sampled":
                meas = _analog_measurements(c, rec, truth["oversample"], problem.sensor_names, declared)
            else:
                meas = fz._measurements(c, rec, truth["oversample"], problem.sensor_names)
            p = dataclasses.replace(problem, acquisition=declared) if acquisition == "declared" else problem
            t0 = time.process_time()
            run = wo.identify(p, data=meas)
            lift, band = run.result.reported_lift
            chi2 = run.result.info.get("adequacy", {}).get("chi2_per_datum", float("nan"))
            true = truth["lift"]
            r = residual_matrix(_LAST["rp"], _LAST["fit"])[: args.head]
            head = float(np.nanmean(r**2))
            print(
                f"{load} from {start}, {rate} Hz, {acquisition}: {lift:.4f} ± {band:.4f} N for {true:.4f} "
                f"({100 * (lift / true - 1):+.1f} %, {(lift - true) / band:+.2f} bands), chi-square {chi2:.2f} "
                f"(first {args.head} samples {head:.2f}), "
                f"{run.status}, {len(run.warnings)} warnings ({time.process_time() - t0:.1f} s CPU)",
                flush=True,
            )
            for w in run.warnings if args.warnings else ():
                print("    ", w)
    return 0


if __name__ == "__main__":
    sys.exit(main())
