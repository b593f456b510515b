"""Geometrically nonlinear membrane: FvK vs linear vs Berger at the seed's loads, speed, and the
linear MHE on nonlinear records (the baseline for the estimator work of issue 11).

Sections (all printed; ``--sections`` picks some):

* ``static``  — static equilibrium under L1, L2, L3, LE at 50..400 Pa: centre deflection, ``∫ w``
  and sensor outputs of the linear model and of Berger, relative to FvK (25x13, both converged in
  the mesh to better than 1e-6).
* ``dynamic`` — the protocol's records (1 cm bubble start, 200 Pa, 1 s at 1 ms) from FvK, Berger and
  the linear model on 25x13: sensor-output error relative to each sensor's peak (max over time
  and RMS), final-deflection L2 error, final ``∫ w`` error, the tension range.
* ``time``    — time-step error of the FvK truth integrator (substeps 1, 2, 4 against 8; 0.3 s).
* ``speed``   — seconds per simulated second: Berger and the cubic modal model (with and without
  sensitivities), FvK, on 25x13 and 49x25.
* ``mhe``     — the existing linear MHE (``wingopt.estimation.identify(problem, data=CSV)``, the
  ``wingopt identify --data`` path) on FvK truth 49x25, estimator 25x13, 1 % noise, seed 0, for L1
  and LE (and the same loads on linear truth for comparison). Slow (FvK 49x25 records, ~1-2 min
  each); CSVs go to ``--tmp``.

    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 python benchmarks/membrane_nonlinear.py --sections static,dynamic,speed
    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 python benchmarks/membrane_nonlinear.py --sections mhe
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from wingopt.fe import load_vector
from wingopt.membrane import (
    BergerMembrane,
    CubicModalMembrane,
    FvKMembrane,
    bubble,
    simulate_berger,
    simulate_fvk,
    simulate_record,
    simulate_response,
    truth_load,
)
from wingopt.problem import load_problem

LOADS = ("L1", "L2", "L3", "LE")


def _centre(model, z):
    p = model.problem
    return float(model.space.evaluate(z, np.array([p.width / 2]), np.array([p.height / 2]))[0])


KAPPA = 1.45
"""Stretch gain of the calibrated Berger model (fitted to FvK's sensor sum on L1–L3, 100–400 Pa)."""


def section_static(problem) -> None:
    print("\n== static: linear, Berger and Berger kappa=1.45 relative to FvK (25x13) ==")
    fvk = FvKMembrane(problem)
    lin = fvk.linear
    models = (("lin", None), ("Ber", BergerMembrane(lin)), ("Bk", BergerMembrane(lin, stretch_gain=KAPPA)))
    print(
        f"{'load':5} {'Pa':>4} {'w_c FvK mm':>10} "
        + " ".join(f"{m + ' w_c':>8}" for m, _ in models)
        + " "
        + " ".join(f"{m + ' ∫w':>8}" for m, _ in models)
        + " "
        + " ".join(f"{m + ' s':>7}" for m, _ in models)
        + "  (relative differences; s: largest over the 4 sensors)"
    )
    for name in LOADS:
        for amp in (50.0, 100.0, 200.0, 400.0):
            load = truth_load(name, problem.width, problem.height, amp)
            p = load_vector(fvk.space, load)
            zf = fvk.static(p).z
            zs = [lin.static_deflection(lin.project(load)) if m is None else m.static(p) for _, m in models]
            vf, sf, cf = lin.basis_integrals @ zf, lin.sensors.outputs(zf), _centre(lin, zf)
            centre = [_centre(lin, z) / cf - 1 if name != "L2" else np.nan for z in zs]
            vol = [(lin.basis_integrals @ z) / vf - 1 if name != "L2" else np.nan for z in zs]
            sens = [np.max(np.abs(lin.sensors.outputs(z) / sf - 1)) for z in zs]
            print(
                f"{name:5} {amp:4.0f} {cf * 1e3:10.3f} "
                + " ".join(f"{v:+8.3f}" for v in centre + vol)
                + " "
                + " ".join(f"{v:7.3f}" for v in sens)
            )


def section_dynamic(problem) -> None:
    print("\n== dynamic: protocol records (bubble start, 200 Pa, 1 s) on 25x13, vs FvK (2 substeps) ==")
    fvk = FvKMembrane(problem)
    lin = fvk.linear
    z0 = lin.project(bubble(problem.width, problem.height))
    roms = {r: CubicModalMembrane(fvk, r) for r in (10, 20)}
    print(
        f"{'load':5} {'model':12} {'s max err':>9} {'s rms err':>9} {'s final':>8} {'w final L2':>10} {'∫w final':>9} "
        f"{'Tx range N/m':>14} {'Ty range N/m':>14}   (errors relative to each sensor's peak / to FvK)"
    )
    for name in LOADS:
        f = lin.project(truth_load(name, problem.width, problem.height))
        ref = simulate_fvk(fvk, f, 1.0, z0=z0, substeps=2)
        sref = lin.sensors.outputs(ref.z)
        peak = np.max(np.abs(sref), axis=0)
        runs = []
        for label, kappa in (("berger", 1.0), ("berger k", KAPPA)):
            tb = simulate_berger(BergerMembrane(lin, stretch_gain=kappa), f, 1.0, z0=z0, substeps=2)
            runs.append((label, tb.z, tb.outputs, tb.tensions))
        for r, rom in roms.items():
            for sub in (1, 2):
                tm = rom.simulate(f, 1.0, z0=z0, substeps=sub)
                runs.append((f"modal{r} s{sub}", tm.z, tm.outputs, tm.tensions))
        tl = simulate_response(lin, f, 1.0, z0=z0)
        runs.append(("linear", tl.z, tl.outputs, None))
        for label, Z, S, T in runs:
            err = (S - sref) / peak
            fin = np.max(np.abs(S[-1] / sref[-1] - 1))
            wl2 = lin.l2_norm(Z[-1] - ref.z[-1]) / lin.l2_norm(ref.z[-1])
            vol = (lin.basis_integrals @ Z[-1]) / (lin.basis_integrals @ ref.z[-1]) - 1 if name != "L2" else np.nan
            tr = (
                ""
                if T is None
                else f"{T[:, 0].min():6.2f}-{T[:, 0].max():6.2f} {T[:, 1].min():6.2f}-{T[:, 1].max():6.2f}"
            )
            print(
                f"{name:5} {label:12} {np.max(np.abs(err)):9.4f} {np.sqrt(np.mean(err**2)):9.4f} {fin:8.4f} "
                f"{wl2:10.4f} {vol:+9.4f}   {tr}"
            )


def section_time(problem) -> None:
    print("\n== time step: FvK exponential integrator, L1, 0.3 s, 25x13, against 8 substeps ==")
    fvk = FvKMembrane(problem)
    lin = fvk.linear
    f = lin.project(truth_load("L1", problem.width, problem.height))
    z0 = lin.project(bubble(problem.width, problem.height))
    ref = lin.sensors.outputs(simulate_fvk(fvk, f, 0.3, z0=z0, substeps=8).z)
    for s in (1, 2, 4):
        t0 = time.process_time()
        out = lin.sensors.outputs(simulate_fvk(fvk, f, 0.3, z0=z0, substeps=s).z)
        print(
            f"substeps {s}: max sensor error {np.max(np.abs(out - ref)) / np.max(np.abs(ref)):.2e} of the peak, "
            f"{time.process_time() - t0:.1f} s CPU"
        )


def section_speed(problem) -> None:
    print("\n== speed: CPU seconds per simulated second (1 kHz, bubble start, L1) ==")
    for nodes in ((25, 13), (49, 25)):
        fvk = FvKMembrane(problem, nodes)
        lin = fvk.linear
        f = lin.project(truth_load("L1", problem.width, problem.height))
        z0 = lin.project(bubble(problem.width, problem.height))
        berger = BergerMembrane(lin)
        t0 = time.process_time()
        roms = {r: CubicModalMembrane(fvk, r) for r in (10, 20)}
        print(
            f"{nodes[0]}x{nodes[1]} building the cubic modal models (r = 10 and 20): {time.process_time() - t0:.1f} s"
        )
        for label, model, kw in (
            ("berger", berger, {}),
            ("berger+sens", berger, {"sensitivities": True}),
            ("berger 2 substeps", berger, {"substeps": 2}),
            ("modal r10", roms[10], {}),
            ("modal r20", roms[20], {}),
            ("modal r20+sens", roms[20], {"sensitivities": True}),
            ("fvk 2 substeps", fvk, {"substeps": 2}),
        ):
            t0 = time.process_time()
            dur = 0.2 if model is fvk else 1.0
            if isinstance(model, CubicModalMembrane):
                model.simulate(f, dur, z0=z0, **kw)
            else:
                (simulate_fvk if model is fvk else simulate_berger)(model, f, dur, z0=z0, **kw)
            print(f"{nodes[0]}x{nodes[1]} {label:18} {(time.process_time() - t0) / dur:7.2f} s per s")


def _write_csv(path: str, rec) -> None:
    head = "t," + ",".join(rec.sensor_names)
    np.savetxt(path, np.column_stack([rec.t, rec.values]), delimiter=",", header=head, comments="", fmt="%.10e")


def section_mhe(problem, tmp: str) -> None:
    from wingopt.estimation.identify import identify
    from wingopt.estimation.protocol import relative_l2

    print("\n== linear MHE (identify --data) on nonlinear records: truth 49x25, estimator 25x13, 1 % noise, seed 0 ==")
    print(
        f"{'load':5} {'truth':7} {'true lift':>9} {'lift':>8} {'lift err':>9} {'band 1s':>8} {'field err':>9} "
        f"{'wall s':>7}  warnings"
    )
    for truth in ("linear", "fvk"):
        for name in ("L1", "LE"):
            rec = simulate_record(problem, name, truth=truth, noise=0.01, seed=0)
            path = os.path.join(tmp, f"wingopt_nl_{truth}_{name}.csv")
            _write_csv(path, rec)
            run = identify(problem, data=path)
            est = run.load_field()
            ferr = relative_l2(rec.model.space, rec.load, est)
            true = rec.steady_lift
            band = run.result.lift_std[-1] if run.result.lift_std is not None else np.nan
            warn = (
                "; ".join(run.summary().get("warnings", [])) if isinstance(run.summary().get("warnings"), list) else ""
            )
            print(
                f"{name:5} {truth:7} {true:9.4f} {run.lift:8.4f} {run.lift / true - 1:+9.3f} {band:8.4f} "
                f"{ferr:9.3f} {run.wall_s:7.1f}  {warn}"
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--sections", default="static,dynamic,time,speed", help="comma list of static,dynamic,time,speed,mhe"
    )
    ap.add_argument("--tmp", default="/tmp", help="folder for the CSV records of the mhe section")
    args = ap.parse_args()
    problem = load_problem("membrane")
    sections = args.sections.split(",")
    for name in sections:
        t0 = time.perf_counter()
        if name == "mhe":
            section_mhe(problem, args.tmp)
        else:
            globals()[f"section_{name}"](problem)
        print(f"[{name}: {time.perf_counter() - t0:.1f} s]")


if __name__ == "__main__":
    main()
