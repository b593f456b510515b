"""The tension and the lift from buffeting alone: accuracy and CPU on simulated tunnel records.

Each record is a SYNTHETIC steady tunnel record with its truth: the full-order FvK membrane on a
49x25 mesh (the estimator's is 25x13) under a tunnel pressure times a buffeting load factor, clean
sensor outputs at 300 Hz (``.npz`` with ``t``, ``outputs``, ``params`` = [e0x, e0y, damping, ...],
``lift_mean``; names ``LOAD_e<ex>_<ey>_d<damping>_o<order>_fc<corner>_r<rms>_s<seed>_n<frames>.npz``).
The study adds 2 % noise (of each sensor's peak, seed 100 + buffeting seed) and drops 1 % of the
frames, keeps the first ``--frames`` frames, and runs :func:`buffeting_identify` with the
aerodynamic load shapes (leading edge ``x1`` for ``TE`` records, ``x0`` otherwise) and the problem
file's prior (prestrain 0.05 ± 20 %, damping factor 1, log-std log 2). Reported per case: the mean
prestrain's error, its ``|z|`` and posterior std, the lift's error against the true mean lift, its
band and ``|z|``, the informative flag, the screen's ratio and CPU per fit.

    python benchmarks/buffeting_study.py --records DIR --cases 'LE_e0.0[456]_0.0[456]_d1_o2_fc30_r0.03' \\
        --seeds 0 1 2 3 4 --frames 450 1400 --out study.jsonl
"""

from __future__ import annotations

import argparse
import glob
import json
import logging
import os
import re
import sys
import time

import numpy as np

from wingopt.estimation.realistic.buffeting_estimator import buffeting_identify
from wingopt.estimation.realistic.buffeting_fit import full_order_frequencies, modal_frequencies
from wingopt.estimation.realistic.load_model import LoadShapes
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


def one(model, path: str, frames: int, force: bool, check: bool) -> dict:
    name = os.path.basename(path)[:-4]
    seed = int(re.search(r"_s(\d+)_n", name).group(1))
    meas, truth = noisy(path, frames, seed)
    shapes = LoadShapes.aerodynamic(model, 200.0, "x1" if name.startswith("TE") else "x0")
    t0 = time.process_time()
    r = buffeting_identify(model, meas, shapes, force=force)
    cpu = time.process_time() - t0
    em = float(np.mean(truth["prestrain"]))
    L = truth["lift"]
    out = {
        "record": name,
        "frames": meas.count,
        "truth": truth,
        "prestrain": list(r.prestrain),
        "prestrain_std": list(r.prestrain_std),
        "e_err": r.mean_prestrain / em - 1,
        "e_std_rel": r.mean_prestrain_std / em,
        "e_z": (r.mean_prestrain - em) / max(r.mean_prestrain_std, 1e-300),
        "lift": r.lift,
        "lift_std": r.lift_std,
        "lift_err": (r.lift - L) / L if L else None,
        "lift_band": r.lift_std / abs(L) if L else None,
        "lift_abs_err": r.lift - L,
        "lift_z": (r.lift - L) / max(r.lift_std, 1e-300),
        "damping": r.damping,
        "damping_std": r.damping_std,
        "f11": r.f11_hz,
        "tension_ratio": r.tension_ratio,
        "informative": r.informative,
        "static": r.static,
        "adequate": r.adequate,
        "screen": r.screen.ratio,
        "screen_threshold": r.screen.threshold,
        "warnings": r.warnings,
        "cpu_s": cpu,
    }
    best = r.best
    if best is not None:
        out.update(forcing=list(best.forcing), iterations=best.iterations, converged=best.converged,
                   static_chi2=best.static_chi2, spectral_chi2=best.spectral_chi2)  # fmt: skip
        if check:  # the modal tangent's loaded frequencies against the full order's at the optimum
            bp = best.problem
            out["f_modal"] = modal_frequencies(bp, best.theta, 2).tolist()
            out["f_full"] = full_order_frequencies(bp, best.theta, 2).tolist()
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
    ap.add_argument("--force", action="store_true", help="fit the spectrum even when the screen finds no resonance")
    ap.add_argument("--check", action="store_true", help="full-order loaded frequencies at each optimum")
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
            row = one(model, path, frames, a.force, a.check)
            rows.append(row)
            check = f" f11 modal/full {row['f_modal'][0]:.2f}/{row['f_full'][0]:.2f}" if "f_full" in row else ""
            print(
                f"{row['record'][:40]:40s} {row['frames']:5d} e {row['prestrain'][0]:.4f},{row['prestrain'][1]:.4f} "
                f"({100 * row['e_err']:+.1f} %, z {row['e_z']:+.1f}) lift {row['lift']:.3f}±{row['lift_std']:.3f} "
                f"(z {row['lift_z']:+.1f}) f11 {row['f11']:.1f} inf {row['informative']} screen {row['screen']:.1f} "
                f"cpu {row['cpu_s']:.2f}{check}",
                flush=True,
            )
            if a.out:
                with open(a.out, "a") as fh:
                    fh.write(json.dumps(row, default=float) + "\n")
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
