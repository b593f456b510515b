"""The full-field (DIC) estimator on steady loaded records, prestrain off by ±20 %: the issue-24 table.

Truth: the full FvK membrane on 49x25 (the estimator: 25x13), prestrain (0.06, 0.04) or (0.04,
0.06) where the problem file says 0.05; the static equilibrium of a tunnel load (``tunnel-LE``: the
thin-airfoil pressure peaking at the leading edge and acting up to the frame; ``tunnel-bump``: an
off-centre Gaussian), 180 Pa mean; ``--frames`` DIC frames of a 40x20 grid, 10 µm and 1e-4 noise,
2 % of the points missing per frame. For each truth a calibration record is simulated the way the
stand-in's is (no flow, released from the same off-centre push, 0.5 s at 300 Hz, 1 % noise) and run
through ``wingopt calibrate``'s workflow; its problem file is the calibrated prior.

Rows: the problem file's prior (the tension unidentified: the band carries ±20 %), the
calibration's prior, and ``prestrain="fit"`` with the calibration (the field's own pull on the
prestrains, not used by default). Then buffeting records (``--buffeted`` s of the stand-in's
buffeting, 3 % RMS, from the static start; the same loads) in the time-resolved mode without a
calibration: the tension from the frames' dynamics; the lift against the record's mean, the lift
history against the truth's frame by frame. Prints markdown tables (docs/dic.md)::

    OPENBLAS_NUM_THREADS=1 nice python benchmarks/dic_study.py [--frames 450] [--buffeted 1.5] [--no-steady]

The buffeting rows end with the loaded modes' table: each prestrain's error and band, the first
two loaded frequencies measured from the frames' modal spectra (``info["loaded_modes"]``), the
truth's own (its FvK tangent at its static state), the model's at the estimate, what the two
frequencies alone constrain the prestrains to, and the frequency precision that 3 % would need.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import scipy.linalg as sla  # noqa: E402
import scipy.sparse.linalg as spla  # noqa: E402

from wingopt import membrane as wm  # noqa: E402
from wingopt.estimation.fullfield import FullFieldSettings, fullfield_identify  # noqa: E402
from wingopt.fe import integrate  # noqa: E402
from wingopt.membrane.dic_synth import synthesize_frames  # noqa: E402
from wingopt.membrane.loads import push  # noqa: E402
from wingopt.problem import load_problem  # noqa: E402
from wingopt.workflows.calibrate import calibrate_membrane, calibrated_problem_text  # noqa: E402
from wingopt.workflows.studies import load_field  # noqa: E402

TRUTHS = ((0.06, 0.04), (0.04, 0.06))
LOADS = ("tunnel-LE", "tunnel-bump")


def calibrated(problem, fwd, seed: int, folder: Path):
    """The calibration record of ``fwd``'s membrane, calibrated; the problem file it writes, loaded."""
    W, L = problem.width, problem.height
    proto = wm.RecordProtocol(
        t_end=0.5, dt=1 / 300, start="shape", initial_shape=push(W, L), noise_fraction=0.01, seed=seed
    )
    rec = wm.simulate_truth(fwd, wm.PressureLoad("no flow", lambda x, y: 0.0 * x), proto)
    run = calibrate_membrane(problem, rec.measurements)
    path = folder / f"calibrated-{seed}.toml"
    path.write_text(calibrated_problem_text(run))
    return load_problem(path), run


def field_error(truth, load, result, model) -> float:
    P = load_field(result, model)
    num = integrate(truth.space, lambda x, y: (load(x, y) - P(x, y)) ** 2, order=8)
    return float(np.sqrt(num / integrate(truth.space, lambda x, y: load(x, y) ** 2, order=8)))


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=450)
    ap.add_argument("--buffeted", type=float, default=1.5, help="seconds of buffeting records (0: none)")
    ap.add_argument("--no-steady", action="store_true", help="only the buffeting records' table")
    a = ap.parse_args(argv)
    problem = load_problem("membrane")
    rows = [] if a.no_steady else steady(problem, a.frames)
    if a.buffeted > 0:
        rows += buffeted(problem, a.buffeted)
    return rows


def steady(problem, n_frames: int) -> list[dict]:
    """Steady rows: static FvK truth, the file's prior, a calibration's, and the field's pull."""
    W, L = problem.width, problem.height
    rows = []
    print("| truth e0 | load | prior | lift error | band (1 sd) | covered | field error | e0 error (x, y) | CPU s |")
    print("|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for i, e0 in enumerate(TRUTHS):
            fwd = wm.forward_model(problem, "fvk", nodes=(49, 25), params=wm.MembraneParameters(*e0), substeps=8)
            cal_problem, cal = calibrated(problem, fwd, 7 + i, Path(tmp))
            truth = fwd.structure
            for name in LOADS:
                load = wm.tunnel_load(name, W, L)
                z = truth.static(truth.gram @ truth.linear.project(load)).z
                t = np.arange(n_frames) / 300.0
                frames = synthesize_frames(truth, t, np.repeat(z[None], n_frames, 0), seed=100 + i)
                true_lift = integrate(truth.space, load, order=8)
                for label, prob, mode in (
                    ("file ±20 %", problem, "prior"),
                    ("calibration", cal_problem, "prior"),
                    ("calibration, fit", cal_problem, "fit"),
                ):
                    model = wm.MembraneModel.from_problem(prob)
                    c0 = time.process_time()
                    res = fullfield_identify(model, frames, FullFieldSettings(mode="steady", prestrain=mode))
                    cpu = time.process_time() - c0
                    lift, std = float(res.lift[-1]), float(res.lift_std[-1])
                    par = res.info["parameters"]
                    row = {
                        "e0": e0, "load": name, "prior": label, "lift_error": lift / true_lift - 1,
                        "band": std / true_lift, "covered": abs(lift - true_lift) <= std,
                        "field_error": field_error(truth, load, res, model),
                        "e0_error": (par["prestrain_x"] / e0[0] - 1, par["prestrain_y"] / e0[1] - 1), "cpu": cpu,
                    }  # fmt: skip
                    rows.append(row)
                    print(
                        f"| {e0} | {name} | {label} | {100 * row['lift_error']:+.2f} % | {100 * row['band']:.2f} % | "
                        f"{'yes' if row['covered'] else 'NO'} | {100 * row['field_error']:.1f} % | "
                        f"{100 * row['e0_error'][0]:+.1f} %, {100 * row['e0_error'][1]:+.1f} % | {cpu:.1f} |"
                    )
            c = cal.calibration
            print(
                f"|  | calibration of {e0} | | prestrain ({c.parameters['prestrain_x']:.5f} ± "
                f"{c.parameters_std['prestrain_x']:.5f}, {c.parameters['prestrain_y']:.5f} ± "
                f"{c.parameters_std['prestrain_y']:.5f}), r = {c.correlation[0, 1]:+.2f} | | | | | |"
            )
    return rows


def truth_frequencies(structure, load) -> np.ndarray:
    """The truth's first two loaded frequencies (Hz): its own tangent at its static state under ``load``."""
    z = structure.static(structure.gram @ structure.linear.project(load)).z
    u, v = structure.inplane(z)
    K = structure.tangent(z, u, v).tocsc()
    n = structure.n
    kwu = K[:n, n:]
    S = K[:n, :n].toarray() - kwu @ spla.splu(K[n:, n:].tocsc()).solve(kwu.T.toarray())
    lam = sla.eigh(S, structure.mass.toarray(), eigvals_only=True, subset_by_index=[0, 1])
    return np.sqrt(lam) / (2 * np.pi)


def buffeted(problem, seconds: float) -> list[dict]:
    """Time-resolved rows: buffeting FvK records, no calibration (the tension from the frames' dynamics)."""
    W, L = problem.width, problem.height
    model = wm.MembraneModel.from_problem(problem)
    print("\n| truth e0 | load | lift error (mean) | band | covered | history: error RMS / fluctuation RMS | "
          "e0 from the frames (x, y) | chi2/datum | CPU s |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|")
    modes = []
    rows = []
    for i, e0 in enumerate(TRUTHS):
        fwd = wm.forward_model(problem, "fvk", nodes=(49, 25), params=wm.MembraneParameters(*e0), substeps=8)
        for name in LOADS:
            proto = wm.RecordProtocol(
                t_end=seconds, dt=1 / 300, start="static", seed=i,
                load_factor=wm.Buffeting(0.03, 30.0, 2, 2012 + i, seconds + 0.1).factor,
            )  # fmt: skip
            rec = wm.simulate_truth(fwd, wm.tunnel_load(name, W, L), proto)
            frames = synthesize_frames(fwd.structure, rec.trajectory.t, rec.trajectory.z, seed=200 + i)
            c0 = time.process_time()
            res = fullfield_identify(model, frames)
            cpu = time.process_time() - c0
            truth = rec.lift_history
            mean = res.info["steady"]["lift_N"]
            std = res.info["steady"]["lift_std_N"]
            err = res.lift - truth[: res.lift.size]
            dyn = res.info["tension_from_dynamics"]
            e = dyn["prestrain"] if dyn and dyn["used"] else [float("nan")] * 2
            c2 = dyn["chi2_per_datum"] if dyn else float("nan")
            row = {
                "e0": e0, "load": name, "lift_error": mean / truth.mean() - 1, "band": std / truth.mean(),
                "history": float(np.std(err) / np.std(truth)), "covered": abs(mean - truth.mean()) <= std,
            }  # fmt: skip
            par, sd = res.info["parameters"], res.info["parameters_std"]
            row["e0_error"] = (par["prestrain_x"] / e0[0] - 1, par["prestrain_y"] / e0[1] - 1)
            row["e0_band"] = (sd["prestrain_x"] / e0[0], sd["prestrain_y"] / e0[1])
            row["modes"] = res.info["loaded_modes"]
            row["truth_frequencies"] = truth_frequencies(fwd.structure, wm.tunnel_load(name, W, L)).tolist()
            rows.append(row)
            modes.append(row)
            print(
                f"| {e0} | {name} | {100 * row['lift_error']:+.2f} % | {100 * row['band']:.2f} % | "
                f"{'yes' if row['covered'] else 'NO'} | {row['history']:.3f} | {100 * (e[0] / e0[0] - 1):+.1f} %, "
                f"{100 * (e[1] / e0[1] - 1):+.1f} % | {c2:.3f} | {cpu:.1f} |"
            )
    print("\n| truth e0 | load | e0 error (x, y) | band (1 sd) | f11 measured | f21 measured | truth's f11, f21 | "
          "model's at the estimate | e0 std from f11, f21 | f std needed |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in modes:
        m, (ex, ey), (bx, by) = r["modes"], r["e0_error"], r["e0_band"]
        if m is None:
            print(
                f"| {r['e0']} | {r['load']} | {100 * ex:+.1f} %, {100 * ey:+.1f} % | "
                f"{100 * bx:.1f} %, {100 * by:.1f} % |"
            )
            continue
        f, sf, p = m["frequencies_measured_hz"], m["frequencies_std_hz"], m["frequencies_predicted_hz"]
        sr = m["prestrain_std_rel_from_frequencies"]
        print(
            f"| {r['e0']} | {r['load']} | {100 * ex:+.1f} %, {100 * ey:+.1f} % | {100 * bx:.1f} %, {100 * by:.1f} % | "
            f"{f[0]:.2f} ± {sf[0]:.2f} Hz | {f[1]:.2f} ± {sf[1]:.2f} Hz | {r['truth_frequencies'][0]:.2f}, "
            f"{r['truth_frequencies'][1]:.2f} | {p[0]:.2f}, {p[1]:.2f} | ±{100 * sr[0]:.1f} %, ±{100 * sr[1]:.1f} % | "
            f"±{100 * m['frequency_std_rel_needed']:.3f} % |"
        )
    return rows


if __name__ == "__main__":
    main()
