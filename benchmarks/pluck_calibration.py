"""Calibrations from a pluck or a tap (issue 32): localized shapes released at rest, FvK truth 49x25.

    python benchmarks/pluck_calibration.py [--tap] [--cache DIR]

Prints each record's prestrains with their bands against the truth (docs/lab_records.md). The
truth needs 32 sub-steps a sample (a pluck's localized shape makes the full-order FvK step stiff):
about 75 s of CPU per 1 s record; ``--cache`` keeps the records for reruns.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import wingopt as wo
import wingopt.membrane as wm
from wingopt.measurements import Measurements

POSITIONS = ((0.3, 0.35), (0.5, 0.5), (0.7, 0.6))
FACTORS = (0.8, 1.2)


def pluck(W: float, H: float, x0: float, y0: float, sx: float = 0.015, sy: float = 0.008, peak: float = 0.004):
    """A 4 mm Gaussian of about 3 x 1.6 cm at (x0, y0), zero on the frame."""
    frame = lambda x, y: np.sin(np.pi * x / W) * np.sin(np.pi * y / H)  # noqa: E731
    scale = peak / (np.sin(np.pi * x0 / W) * np.sin(np.pi * y0 / H))
    return lambda x, y: scale * np.exp(-((x - x0) ** 2) / (2 * sx**2) - (y - y0) ** 2 / (2 * sy**2)) * frame(x, y)


def record(problem, prestrain, pos, tap: bool, rate=300.0, t_end=1.0, seed=0, noise=0.02) -> Measurements:
    W, H = problem.width, problem.height
    params = wm.MembraneParameters.nominal(problem, prestrain, 1.0)
    fwd = wm.forward_model(problem, "fvk", nodes=(49, 25), params=params, substeps=32)
    x0, y0 = pos[0] * W, pos[1] * H
    if tap:  # a 4 ms pressure pulse on a 1 cm spot, the membrane at rest
        load = wm.PressureLoad("tap", lambda x, y: 3000.0 * np.exp(-((x - x0) ** 2 + (y - y0) ** 2) / (2 * 0.01**2)))
        proto = wm.RecordProtocol(
            t_end=t_end,
            dt=1 / rate,
            start="rest",
            noise_fraction=noise,
            seed=seed,
            load_factor=lambda t: np.where(np.asarray(t) < 0.004, 1.0, 0.0),
        )
    else:
        load = wm.PressureLoad("no flow", lambda x, y: 0.0 * x)
        proto = wm.RecordProtocol(
            t_end=t_end, dt=1 / rate, start="shape", initial_shape=pluck(W, H, x0, y0), noise_fraction=noise, seed=seed
        )
    m = wm.simulate_truth(fwd, load, proto).measurements
    return Measurements(m.t, m.values, m.sensor_names, None, "tap" if tap else "pluck")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tap", action="store_true", help="a short pressure pulse instead of a pluck")
    ap.add_argument("--cache", type=Path, help="keep the simulated records here")
    args = ap.parse_args(argv)
    problem = wo.load_problem("membrane")
    e = problem.material.prestrain
    for factor in FACTORS:
        for pos in POSITIONS:
            truth = (e * factor, e * factor)
            key = (
                args.cache / f"{'tap' if args.tap else 'pluck'}_{factor}_{pos[0]}_{pos[1]}.npz" if args.cache else None
            )
            if key is not None and key.exists():
                z = np.load(key)
                meas = Measurements(z["t"], z["y"], problem.sensor_names, None, "cached")
            else:
                meas = record(problem, truth, pos, args.tap)
                if key is not None:
                    key.parent.mkdir(parents=True, exist_ok=True)
                    np.savez(key, t=meas.t, y=meas.values)
            c0 = time.process_time()
            cal = wo.calibrate_membrane(problem, meas).calibration
            cells = []
            for i, name in enumerate(("prestrain_x", "prestrain_y")):
                v, sd = cal.parameters[name], cal.parameters_std[name]
                cells.append(
                    f"{name} {v:.4f} ± {sd:.4f} ({(v - truth[i]) / sd:+.1f} sd, {100 * (v / truth[i] - 1):+.0f} %)"
                )
            print(
                f"x{factor} at {pos}: {'; '.join(cells)}; chi2/datum {cal.chi2_per_datum:.2f}, "
                f"{len(cal.warnings)} warning(s) ({time.process_time() - c0:.1f} s)",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
