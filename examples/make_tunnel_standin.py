"""Make the wind-tunnel stand-in: a SYNTHETIC record of the seed's test, and its calibration record.

The seed's experiment (latex membrane, 5 % prestrain, 0.14 m x 0.07 m, 18 m/s at 4 deg, stereo DIC
at 300 Hz, four stretch regions) is not available. This script makes a stand-in with the package's
own high-fidelity model, labelled SYNTHETIC in every file header, and states its truth there (the
estimators never read comments):

* truth: the full Föppl–von Kármán membrane on a 49x25 mesh (the estimator uses 25x13), prestrain
  (0.056, 0.046) where the problem file says 0.05, damping as the file;
* load: the thin-airfoil pressure of a cambered plate at 4 deg, peaking at the leading edge
  (x = 0) and acting up to the frame, 180 Pa mean (``tunnel-LE`` of
  :func:`wingopt.membrane.loads.tunnel_load`): centre deflection ~6 mm, deflection-induced
  stretch of the order of the prestrain;
* steady flow: the record starts in the static equilibrium of the mean load (no release
  transient), buffeting ``1 + eps(t)``, 3 % RMS, most of its energy below 30 Hz (second-order
  roll-off above): :class:`wingopt.membrane.loads.Buffeting`;
* 300 Hz, 4.6 s (1381 frames), 2 % Gaussian noise per sensor (of its peak), 1 % of the frames
  dropped (empty cells);
* the calibration record: the same membrane with no flow, released from an off-centre push of
  unknown shape, 0.5 s at 300 Hz, 1 % noise (``wingopt calibrate``);
* the DIC frame set of the same run (the same trajectory, the first 1.5 s: 450 frames): a 40 x 20
  grid of points, 10 µm noise on U, V, W and 1e-4 on the surface Lagrange strains, 2 % of the
  points missing per frame, stored compactly (1 µm and 1e-5 steps, well below the noise) in
  ``tunnel_dic_300Hz.npz`` with the truth beside it (``truth_*`` arrays the readers ignore); its
  first three frames also as DICe solution files (``tunnel_dice/``, in mm, origin and axes as
  ``examples/tunnel_dice.toml`` declares, DICe's in-plane strains): ``docs/dic.md``.

    .venv/bin/python examples/make_tunnel_standin.py     # writes examples/data/tunnel_* (minutes)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from wingopt.measurements.dic import DICMapping
from wingopt.membrane import (
    Buffeting,
    MembraneParameters,
    PressureLoad,
    RecordProtocol,
    forward_model,
    simulate_truth,
    tunnel_load,
)
from wingopt.membrane.dic_synth import synthesize_frames
from wingopt.membrane.loads import push
from wingopt.problem import load_problem
from wingopt.results.dic_files import write_dic_npz, write_dice

DATA = Path(__file__).parent / "data"
PRESTRAIN = (0.056, 0.046)
RATE_HZ = 300.0
DURATION_S = 4.6
SUBSTEPS = 8  # 300 Hz sampling: the integrator's step is 0.42 ms (docs/tunnel.md: 3e-3 of the peak)
TRUTH_NODES = (49, 25)
DIC_FRAMES = 450  # the first 1.5 s of the run
DIC_GRID = (40, 20)
DICE_MAPPING = DICMapping(origin=(-70.0, 35.0), y_axis="-y", unit="mm")  # as examples/tunnel_dice.toml


def write_record(path: Path, meas, header: list[str]) -> Path:
    lines = [f"# {h}" for h in header] + ["t," + ",".join(meas.sensor_names)]
    for t, row in zip(meas.t, meas.values):
        lines.append(f"{t:.6f}," + ",".join("" if np.isnan(v) else f"{v:.9g}" for v in row))
    path.write_text("\n".join(lines) + "\n")
    return path


def main(seed: int = 2012) -> list[Path]:
    problem = load_problem("membrane")
    W, L = problem.width, problem.height
    fwd = forward_model(problem, "fvk", nodes=TRUTH_NODES, params=MembraneParameters(*PRESTRAIN), substeps=SUBSTEPS)
    load = tunnel_load("tunnel-LE", W, L)
    t0 = time.process_time()
    rec = simulate_truth(
        fwd,
        load,
        RecordProtocol(
            t_end=DURATION_S, dt=1 / RATE_HZ, start="static", noise_fraction=0.02, seed=seed, drop=0.01,
            load_factor=Buffeting(0.03, 30.0, 2, seed, DURATION_S + 0.1).factor,
        ),
    )  # fmt: skip
    cpu = time.process_time() - t0
    z = rec.trajectory.z
    wc = fwd.model.space.evaluate(z.mean(axis=0), np.array([W / 2]), np.array([L / 2]))[0]
    lift = float(np.mean(rec.lift_history))
    mean_lift = rec.true_lift / float(rec.load_factor[-1])
    header = [
        "SYNTHETIC wind-tunnel stand-in made by examples/make_tunnel_standin.py (not measured data)",
        f"truth: Foppl-von Karman membrane {TRUTH_NODES[0]}x{TRUTH_NODES[1]}, prestrain {PRESTRAIN}, "
        f"steady start, tunnel-LE load {load.description}",
        f"buffeting 3 % RMS (corner 30 Hz, 2nd order), 300 Hz, 2 % noise, 1 % frames dropped, seed {seed}",
        f"true mean lift {mean_lift:.6f} N (steady load); mean of the lift history {lift:.6f} N; "
        f"centre deflection {1000 * wc:.2f} mm",
    ]
    out = [write_record(DATA / "tunnel_300Hz.csv", rec.measurements, header)]
    n = rec.measurements.count
    print(f"tunnel record: {n} frames, lift {mean_lift:.4f} N, wc {1000 * wc:.2f} mm, {cpu:.0f} s CPU")
    cal = simulate_truth(
        fwd,
        PressureLoad("no flow", lambda x, y: 0.0 * x),
        RecordProtocol(
            t_end=0.5, dt=1 / RATE_HZ, start="shape", initial_shape=push(W, L), noise_fraction=0.01, seed=seed + 1
        ),
    )
    header = [
        "SYNTHETIC calibration record made by examples/make_tunnel_standin.py (not measured data)",
        f"truth: Foppl-von Karman membrane {TRUTH_NODES[0]}x{TRUTH_NODES[1]}, prestrain {PRESTRAIN}, no flow, "
        "released at rest from an off-centre push (shape unknown to the estimator), 300 Hz, 1 % noise",
    ]
    out.append(write_record(DATA / "tunnel_calibration_300Hz.csv", cal.measurements, header))
    out += write_dic(fwd, rec, seed)
    return out


def write_dic(fwd, rec, seed: int) -> list[Path]:
    """The DIC frame set of the same run: NPZ (450 frames) and three DICe solution files."""
    t, z = rec.trajectory.t[:DIC_FRAMES], rec.trajectory.z[:DIC_FRAMES]
    lift = rec.lift_history[:DIC_FRAMES]
    note = (
        f"SYNTHETIC DIC frames of the tunnel stand-in (examples/make_tunnel_standin.py, seed {seed}): the run of "
        f"tunnel_300Hz.csv, first {DIC_FRAMES} frames; true mean lift over them {lift.mean():.6f} N"
    )
    kw = {"grid": DIC_GRID, "noise_displacement": 1e-5, "noise_strain": 1e-4, "missing": 0.02}
    frames = synthesize_frames(fwd.structure, t, z, seed=seed + 2, source=note, **kw)
    truth = {  # beside the data; the readers ignore them
        "truth_lift": lift,
        "truth_load_factor": rec.load_factor[:DIC_FRAMES],
        "truth_load": np.array("tunnel-LE"),
        "truth_prestrain": np.array(PRESTRAIN),
    }
    quantum = {"u": 1e-6, "v": 1e-6, "w": 1e-6, "exx": 1e-5, "eyy": 1e-5, "exy": 1e-5}
    path = write_dic_npz(frames, DATA / "tunnel_dic_300Hz.npz", quantum=quantum, extra=truth)
    dice = synthesize_frames(fwd.structure, t[:3], z[:3], seed=seed + 3, source=note, strain_kind="inplane", **kw)
    files = write_dice(dice, DATA / "tunnel_dice", DICE_MAPPING)
    print(f"DIC: {frames.n_frames} frames x {frames.n_points} points -> {path} ({path.stat().st_size >> 10} KiB)")
    return [path, *files]


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
