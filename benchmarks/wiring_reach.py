"""What the wiring checks can tell on transient records: clean records under loads in and outside the
thin-airfoil shapes, and a gain set wrong by 0.1x-10x on one sensor.

Records as ``benchmarks/fuzz_records.py`` makes them (FvK truth 37x19 full order, prestrains x1.1 and
x0.9 of the file's, 1 % noise, 1 s at 300 Hz, point-sampled), released from the bubble or loaded
from rest; one seed per load (a bump's place is drawn from it). The checks run as the transient
route runs them (:func:`wingopt.estimation.steady.wiring.attach` on the record). One row per record
and mistake: the finding's sensors, its ratio and whether it names the sensor set wrong::

    python benchmarks/wiring_reach.py [--loads L1,LE,bump] [--starts bubble,rest] [--gains 0.1,0.5,2,10]
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import daq_transient  # noqa: E402 - the DAQ records' cases, beside this file
import fuzz_records as fz  # noqa: E402 - the fuzz's generator, beside this file

import wingopt as wo  # noqa: E402
from wingopt.estimation.core.record_settings import RecordSettings  # noqa: E402
from wingopt.estimation.steady.wiring import attach  # noqa: E402
from wingopt.membrane import MembraneModel  # noqa: E402

LOADS = ("L1", "L2", "L3", "LE", "bump", "two-peaks", "te-peak", "sharp-le", "steep-span", "uniform")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--loads", default=",".join(LOADS), help="comma-separated fuzz loads")
    ap.add_argument("--starts", default="bubble,rest")
    ap.add_argument("--gains", default="", help="gains set wrong on --sensor (a row each, beside the clean one)")
    ap.add_argument("--sensor", type=int, default=1, help="the sensor set wrong (0-based)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    gains = [None] + [float(g) for g in args.gains.split(",") if g]
    counts = {"clean": [0, 0], "wrong": [0, 0, 0]}  # clean: records, findings; wrong: records, named right, named other
    for start in args.starts.split(","):
        for i, load in enumerate(args.loads.split(",")):
            c = daq_transient.case(load, start, 300, 100 + i) | {"daq": "point"}
            problem = wo.load_problem("membrane").with_identification(
                initial_deflection=0.01 if start == "bubble" else 0.0
            )
            rec, _, truth = fz.simulate(c, problem)
            p0 = truth["side"] * abs(problem.identification.initial_load)
            problem = problem.with_identification(initial_load=p0)
            meas = fz._measurements(c, rec, truth["oversample"], problem.sensor_names)
            model = MembraneModel.from_problem(problem)
            names = problem.sensor_names
            for gain in gains:
                y = meas.values.copy()
                if gain is not None:
                    y[:, args.sensor] *= gain
                info = {"warnings": []}
                attach(info, model, meas.t, y, RecordSettings(), p0, steady=False)
                w = info["wiring"]
                f = w["findings"][0] if w["findings"] else None
                said = "no finding" if f is None else f"{f['mistake']} {'/'.join(f['sensors'])} ({f['ratio']:.2g}x)"
                said += (
                    f" (as wired: chi-square {w['baseline_chi2']:.3g} per mean)"
                    if w["checked"]
                    else f" ({w['reason']})"
                )
                if gain is None:
                    counts["clean"][0] += 1
                    counts["clean"][1] += f is not None
                    what = "clean"
                else:
                    right = f is not None and f["sensors"] == (names[args.sensor],)
                    counts["wrong"][0] += 1
                    counts["wrong"][1] += right
                    counts["wrong"][2] += f is not None and not right
                    what = f"{names[args.sensor]} at {gain:g}x" + (" (named)" if right else "")
                print(f"{load:10s} from {start:6s} {what:18s}: {said}", flush=True)
    n, k = counts["clean"]
    print(f"clean records with a finding: {k} of {n}")
    if counts["wrong"][0]:
        n, right, other = counts["wrong"]
        print(f"records wired wrong: {right} of {n} name the sensor, {other} name another, {n - right - other} none")
    return 0


if __name__ == "__main__":
    sys.exit(main())
