"""Make the buffeting tests' records: tests/data/buffeting_*.npz (SYNTHETIC, minutes of CPU).

Truth: the full-order Föppl–von Kármán membrane on a 49x25 mesh (the estimator's is 25x13: no
inverse crime) with the prestrain 20 % off the problem file's 0.05, under the tunnel's thin-airfoil
leading-edge pressure (``tunnel-LE``, 180 Pa mean, acting up to the frame) times a buffeting load
factor (3 % RMS, corner 30 Hz, second order), started in the static equilibrium, sampled at 300 Hz
for 1.5 s. Stored CLEAN (the tests add their own noise): the times, the sensor outputs, the sensor
outputs of the static equilibrium under the mean load (a record without buffeting is those plus
noise), the true mean lift and the truth's prestrains.

    .venv/bin/python tests/data/make_buffeting_records.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from wingopt.membrane import Buffeting, MembraneParameters, RecordProtocol, forward_model, simulate_truth, tunnel_load
from wingopt.problem import load_problem

HERE = Path(__file__).parent
RATE_HZ, DURATION_S, NODES, SUBSTEPS = 300.0, 1.5, (49, 25), 8
RECORDS = {"buffeting_e040_300Hz.npz": (0.04, 0.04, 3), "buffeting_e060_300Hz.npz": (0.06, 0.06, 4)}


def make(name: str, ex: float, ey: float, seed: int) -> Path:
    problem = load_problem("membrane")
    fwd = forward_model(problem, "fvk", nodes=NODES, params=MembraneParameters(ex, ey), substeps=SUBSTEPS)
    load = tunnel_load("tunnel-LE", problem.width, problem.height)
    t0 = time.process_time()
    protocol = RecordProtocol(
        t_end=DURATION_S,
        dt=1 / RATE_HZ,
        start="static",
        noise_fraction=0.0,
        seed=None,
        load_factor=Buffeting(0.03, 30.0, 2, seed, DURATION_S + 0.1).factor,
    )
    rec = simulate_truth(fwd, load, protocol)
    model = fwd.model
    zbar = fwd.equilibrium(model.project(load))
    static = model.sensors.outputs(zbar)
    path = HERE / name
    np.savez_compressed(
        path,
        t=rec.measurements.t,
        outputs=rec.trajectory.outputs,
        static_outputs=static,
        lift_mean=rec.true_lift / float(rec.load_factor[-1]),
        prestrain=np.array([ex, ey]),
        description=np.array(
            f"SYNTHETIC: FvK {NODES[0]}x{NODES[1]}, prestrain ({ex}, {ey}), tunnel-LE, buffeting 3 % rms "
            f"30 Hz order 2 seed {seed}, {RATE_HZ:g} Hz, {DURATION_S} s, clean outputs"
        ),
    )
    print(
        f"{path.name}: {rec.measurements.count} frames, mean lift {float(rec.true_lift / rec.load_factor[-1]):.4f} N, "
        f"{time.process_time() - t0:.0f} s CPU"
    )
    return path


if __name__ == "__main__":
    names = sys.argv[1:] or list(RECORDS)
    for n in names:
        make(n, *RECORDS[n])
