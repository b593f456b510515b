"""Steady tunnel records: the lift and the tension from the sensors alone, accuracy and CPU.

Each record is a SYNTHETIC steady tunnel record with its truth: the full-order FvK membrane on a
49x25 mesh (the estimator's is 25x13) under a tunnel pressure times a buffeting load factor, clean
sensor outputs at 300 Hz (``.npz`` with ``t``, ``outputs``, ``params`` = [e0x, e0y, damping, ...],
``lift_mean``; names ``LOAD_e<ex>_<ey>_d<damping>_o<order>_fc<corner>_r<rms>_s<seed>_n<frames>.npz``).
The study adds 2 % noise (of each sensor's peak, seed 100 + buffeting seed) and drops 1 % of the
frames, keeps the first ``--frames`` frames, and runs the steady estimator
(:func:`~wingopt.estimation.steady.estimator.steady_identify`, what ``wingopt identify``
runs on a steady record) with ``[identification] pressure_prior = --prior`` (``auto``: a load that
may act up to the frame; ``aerodynamic``: thin-airfoil shapes, leading edge ``x1`` for ``TE``
records, ``x0`` otherwise) and the problem file's prior (prestrain 0.05 ± 20 %, damping factor 1).
Reported per case: the mean prestrain's error, its ``|z|`` and posterior std, the lift's error
against the true mean lift, its band and ``|z|``, whether the buffeting identified the tension,
adequacy, the screen's ratio and CPU per fit (warm: the modal model is built once).

    python benchmarks/tunnel_study.py --records DIR --cases 'LE_e0.0[456]_0.0[456]_d1_o2_fc30_r0.03' \\
        --seeds 0 1 2 3 4 --frames 450 1400 --prior auto --out study.jsonl
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
import json
import logging
import os
import re
import sys
import time

import numpy as np

from wingopt.estimation.core.record_settings import RecordSettings
from wingopt.estimation.steady.estimator import steady_identify
from wingopt.measurements import Measurements
from wingopt.membrane import MembraneModel, add_noise
from wingopt.problem import load_problem

log = logging.getLogger("buffeting_study")

DEFAULT_CASES = [
    "LE_e0.04_0.04_d1_o2_fc30_r0.03",
    "LE_e0.05_0.05_d1_o2_fc30_r0.03",
    "LE_e0.06_0.06_d1_o2_fc30_r0.03",
]
EXTRA_CASES = [
    "TE_e0.05_0.05_d1_o2_fc30_r0.03",
    "anti_e0.05_0.05_d1_o2_fc30_r0.03",
    "bump_e0.05_0.05_d1_o2_fc30_r0.03",
    "LE_e0.05_0.05_d2_o2_fc30_r0.03",
    "LE_e0.05_0.05_d1_o1_fc30_r0.03",
]


def noisy(path: str, frames: int, seed: int, noise: float = 0.02, drop: float = 0.01) -> tuple[Measurements, dict]:
    """The record's first ``frames`` frames with noise and dropped frames, and its truth."""
    d = np.load(path)
    clean = d["outputs"][:frames]
    y, _ = add_noise(clean, noise, 100 + seed)
    lost = np.random.default_rng(200 + seed).random(clean.shape[0]) < drop
    lost[0] = False
    y[lost] = np.nan
    p = d["params"]
    truth = {"prestrain": [float(p[0]), float(p[1])], "damping": float(p[2]), "lift": float(d["lift_mean"])}
    return Measurements(d["t"][:frames], y, ("S1", "S2", "S3", "S4")), truth


def one(base, path: str, frames: int, prior: str, bin_hz: float, calibration: float | None = None) -> dict:
    name = os.path.basename(path)[:-4]
    seed = int(re.search(r"_s(\d+)_n", name).group(1))
    meas, truth = noisy(path, frames, seed)
    ident = dataclasses.replace(
        base.problem.identification, pressure_prior=prior, leading_edge="x1" if name.startswith("TE") else "x0"
    )
    if calibration is not None:
        # a calibration's posterior as `wingopt calibrate` writes it: each prestrain off the truth by
        # `calibration` (relative; x high, y low), 1-sigma 0.001, the two strongly anticorrelated
        ex, ey = truth["prestrain"]
        ident = dataclasses.replace(
            ident,
            prestrain=(ex * (1 + calibration), ey * (1 - calibration)),
            prestrain_std=(0.001, 0.001),
            prestrain_correlation=-0.9,
        )
    model = dataclasses.replace(base, problem=dataclasses.replace(base.problem, identification=ident))
    t0 = time.process_time()
    res = steady_identify(model, meas, RecordSettings(membrane_model="fvk", spectrum_bin_hz=bin_hz))
    cpu = time.process_time() - t0
    info, tension = res.info, res.info["tension"]
    lift, lift_std = res.reported_lift
    em = float(np.mean(truth["prestrain"]))
    L = truth["lift"]
    out = {
        "record": name,
        "frames": meas.count,
        "prior": prior,
        "bin_hz": bin_hz,
        "truth": truth,
        "prestrain": [info["parameters"]["prestrain_x"], info["parameters"]["prestrain_y"]],
        "e_err": tension["mean_prestrain"] / em - 1,
        "e_std_rel": tension["mean_prestrain_std"] / em,
        "e_z": (tension["mean_prestrain"] - em) / max(tension["mean_prestrain_std"], 1e-300),
        "lift": lift,
        "lift_std": lift_std,
        "lift_err": (lift - L) / L if L else None,
        "lift_band": lift_std / abs(L) if L else None,
        "lift_abs_err": lift - L,
        "lift_z": (lift - L) / max(lift_std, 1e-300),
        "f11": tension["loaded_f11_hz"],
        "tension_ratio": tension["posterior_over_prior"],
        "informative": tension["source"] == "buffeting",
        "adequate": info["model_adequate"],
        "screen": tension["screen"]["ratio"] if tension["screen"] else float("nan"),
        "solutions": info["solutions"],
        "warnings": info["warnings"],
        "cpu_s": cpu,
    }
    return out


def table(rows: list[dict]) -> str:
    """Markdown table: one line per (case, frames)."""
    head = (
        "| case | frames | n | prestrain err mean / RMS / max (%) | max |z| | post std (%) | lift err mean / RMS / "
        "max (%) | lift band (%) | max |z_lift| | informative | adequate | screen | CPU s |"
    )
    lines = [head, "|" + "---|" * 13]
    groups: dict = {}
    for r in rows:
        groups.setdefault((re.sub(r"_s\d+_n\d+$", "", r["record"]), r["frames"]), []).append(r)
    for (case, frames), g in sorted(groups.items()):
        e = 100 * np.array([r["e_err"] for r in g])
        ez = np.array([abs(r["e_z"]) for r in g])
        es = 100 * np.array([r["e_std_rel"] for r in g])
        if all(r["lift_err"] is not None for r in g):
            le = 100 * np.array([r["lift_err"] for r in g])
            lift = f"{le.mean():+.1f} / {np.sqrt(np.mean(le**2)):.1f} / {np.abs(le).max():.1f}"
            band = f"{100 * np.mean([r['lift_band'] for r in g]):.1f}"
        else:
            la = np.array([r["lift_abs_err"] for r in g])
            lift = f"abs {la.mean():+.3f} N"
            band = f"±{np.mean([r['lift_std'] for r in g]):.3f} N"
        lz = max(abs(r["lift_z"]) for r in g)
        inf = sum(r["informative"] for r in g)
        ok = sum(r["adequate"] for r in g)
        scr = np.mean([r["screen"] for r in g])
        cpu = np.mean([r["cpu_s"] for r in g])
        lines.append(
            f"| {case} | {frames} | {len(g)} | {e.mean():+.1f} / {np.sqrt(np.mean(e**2)):.1f} / {np.abs(e).max():.1f} "
            f"| {ez.max():.1f} | {es.mean():.1f} | {lift} | {band} | {lz:.1f} | {inf}/{len(g)} | {ok}/{len(g)} "
            f"| {scr:.1f} | {cpu:.2f} |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", default=os.environ.get("WINGOPT_TUNNEL_RECORDS", "records"), help="record folder")
    ap.add_argument("--cases", nargs="*", help="case names (globs; default: LE at 0.04/0.05/0.06; none: --cases)")
    ap.add_argument("--extra", action="store_true", help="add the TE, anti, bump, damping x2 and order-1 cases")
    ap.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2, 3, 4])
    ap.add_argument("--frames", nargs="*", type=int, default=[450, 1400])
    ap.add_argument("--prior", default="auto", choices=("auto", "frame", "aerodynamic", "interior"))
    ap.add_argument("--bin-hz", type=float, default=RecordSettings.spectrum_bin_hz, help="spectral bin width (Hz)")
    ap.add_argument("--calibration", type=float, help="a calibrated prior this far off the truth (relative)")
    ap.add_argument("--out", help="append one JSON line per fit")
    ap.add_argument("--table", help="only print the table of a JSON-lines file")
    ap.add_argument("-v", "--verbose", action="store_true")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING, format="%(message)s")
    if a.table:
        with open(a.table) as fh:
            print(table([json.loads(line) for line in fh if line.strip()]))
        return 0
    cases = (DEFAULT_CASES if a.cases is None else a.cases) + (EXTRA_CASES if a.extra else [])
    paths = []
    for c in cases:
        for s in a.seeds:
            found = sorted(glob.glob(os.path.join(a.records, f"{c}_s{s}_n*.npz")))
            paths += [p for p in found if re.search(r"_n\d+\.npz$", p)]
    if not paths:
        print(f"no records for {cases} seeds {a.seeds} in {a.records}", file=sys.stderr)
        return 2
    model = MembraneModel.from_problem(load_problem("membrane"))
    rows = []
    for path in paths:
        for frames in a.frames:
            row = one(model, path, frames, a.prior, a.bin_hz, a.calibration)
            rows.append(row)
            print(
                f"{row['record'][:40]:40s} {row['frames']:5d} e {row['prestrain'][0]:.4f},{row['prestrain'][1]:.4f} "
                f"({100 * row['e_err']:+.1f} %, z {row['e_z']:+.1f}) lift {row['lift']:.3f}±{row['lift_std']:.3f} "
                f"(z {row['lift_z']:+.1f}) f11 {row['f11']:.1f} inf {row['informative']} screen {row['screen']:.1f} "
                f"cpu {row['cpu_s']:.2f}",
                flush=True,
            )
            if a.out:
                with open(a.out, "a") as fh:
                    fh.write(json.dumps(row, default=float) + "\n")
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
