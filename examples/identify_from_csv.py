"""Identify the membrane's load and lift from a measured-style CSV record (wind-tunnel use case).

The record ``examples/data/synthetic_tunnel_300Hz.csv`` is **SYNTHETIC** (made by
``make_synthetic_tunnel_data.py``: a leading-edge-peaked lift on a finer mesh, the flow starting at
t = 0 with the membrane at rest and the load rising over 40 ms, 300 Hz, 2 % noise, dropped frames).
It stands in for the seed's DIC data at 300 Hz, which are not available.

What a user should choose for such data, and why:

* ``load_model="constant"`` (the default): in a steady tunnel run the load is constant once the flow
  has started, so every sample tells about the same load and the information accumulates over the
  whole record (the final window reproduces the batch estimate: the smallest error bar). The
  estimator's consistency test leaves out the start it cannot explain (here the first 50 ms,
  while the load ramps up) and restarts the estimate if the data stop being consistent with one
  constant load (the number of restarts is printed: 0 means the run was steady).
* ``load_model="random_walk"`` (``--load-model random_walk``) for a load that varies (a speed
  sweep, gusts): each 0.05 s block gets its own load, so the history follows the changes, at the
  price of a noisier estimate (each block sees only its own data for the amplitude).
* The window is given in seconds (0.2 s, whatever the sample rate: 60 samples at 300 Hz).
* ``initial_deflection=0``: the membrane's initial shape is unknown (the problem file's 1 cm bubble
  belongs to the simulated protocol); ``initial_load`` (200 Pa in the problem file) only fixes the
  sign: stretch sensors cannot tell a load from its negative.
* The noise level is estimated from the data (no ``noise_std`` given).

The true lift in the file's header is printed for comparison only; the estimator never reads it.

    .venv/bin/python examples/identify_from_csv.py [FILE.csv] [--load-model constant|random_walk]
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np

from wingopt.estimation.mhe import MHESettings, mhe_identify
from wingopt.measurements.csv_file import read_measurements
from wingopt.membrane import MembraneModel
from wingopt.problem import load_problem

DATA = Path(__file__).parent / "data" / "synthetic_tunnel_300Hz.csv"


def true_lift_from_header(path: Path) -> float | None:
    """The ``true lift X N`` of a synthetic file's comment header (for the printout only)."""
    for line in Path(path).read_text().splitlines():
        if not line.startswith("#"):
            break
        m = re.search(r"true lift ([0-9.eE+-]+) N", line)
        if m:
            return float(m.group(1))
    return None


def main(path: Path | str = DATA, load_model: str = "constant", quiet: bool = False) -> dict:
    """Run the MHE on ``path`` and print the lift; returns the key numbers as a dict."""
    problem = load_problem("membrane")
    model = MembraneModel.from_problem(problem)
    meas, report = read_measurements(path, problem.sensor_names)
    settings = MHESettings(load_model=load_model)
    res = mhe_identify(model, meas, settings, initial_deflection=0.0)
    info = res.info
    t, lift, std = res.t, res.lift, res.lift_std
    half = t >= t[0] + 0.5 * (t[-1] - t[0])
    out = {
        "samples": int(meas.count),
        "missing_rows": report.missing_rows,
        "dt_s": report.dt,
        "load_model": load_model,
        "window_samples": info["window"],
        "onset_skipped_s": float(info["onset"]["t_start"] - meas.t[0]),
        "restarts": len(info["restarts"]),
        "lift_N": float(lift[-1]),
        "lift_std_N": float(std[-1]),
        "lift_mean_last_half_N": float(np.mean(lift[half])),
        "lift_spread_last_half_N": float(np.ptp(lift[half])),
        "noise_std": [float(s) for s in info["noise_std"]],
        "true_lift_N": true_lift_from_header(path),
    }
    if out["true_lift_N"]:
        out["lift_error"] = (out["lift_N"] - out["true_lift_N"]) / out["true_lift_N"]
    if quiet:
        return out
    print(f"{path}: {meas.count} samples at {1 / report.dt:.0f} Hz, {report.missing_rows} missing rows skipped")
    print(
        f"MHE ({load_model} load, window {info['window']} samples = {info['window_s']:.2f} s, "
        f"lambda {res.regularization:.3g} from the data, noise estimated from the data)"
    )
    print(
        f"load onset: the first {out['onset_skipped_s'] * 1000:.0f} ms are not explained by the load model "
        f"and were left out; restarts: {out['restarts']}"
    )
    print(f"final lift: {out['lift_N']:.4f} ± {out['lift_std_N']:.4f} N (1 sigma)")
    print("lift history:")
    for tq in np.linspace(t[0], t[-1], 6):
        k = int(np.argmin(np.abs(t - tq)))
        print(f"  t = {t[k]:6.3f} s   {lift[k]:.4f} ± {std[k]:.4f} N")
    print(
        f"last half of the record: mean {out['lift_mean_last_half_N']:.4f} N, "
        f"peak-to-peak {out['lift_spread_last_half_N']:.4f} N"
    )
    if out["true_lift_N"]:
        print(
            f"true lift from the SYNTHETIC file's header (not used by the estimator): {out['true_lift_N']:.4f} N "
            f"-> error {100 * out['lift_error']:+.1f} %"
        )
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="MHE load identification from a CSV record")
    ap.add_argument("path", nargs="?", default=str(DATA))
    ap.add_argument("--load-model", choices=("constant", "random_walk"), default="constant")
    args = ap.parse_args()
    main(Path(args.path), args.load_model)
    sys.exit(0)
