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
* ``speed``   — seconds per simulated second: the full-order Berger and FvK models, the modal FvK
  model (all modes, cubic stiffness on the lowest 10 or 20), and the modal models' exact tangents
  (three parameter directions), on 25x13 and 49x25.
* ``mhe``     — the linear MHE through ``wingopt.workflows.identify(problem, data=CSV,
  method="mhe")`` (the ``wingopt identify --data --method mhe`` path) on FvK truth 49x25,
  estimator 25x13, 1 % noise, seed 0, for L1 and LE (and the same loads on linear truth for
  comparison). Slow (FvK 49x25 records, ~1-2 min each); CSVs go to ``--tmp``.

    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 python benchmarks/membrane_nonlinear.py --sections static,dynamic,speed
    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 python benchmarks/membrane_nonlinear.py --sections mhe
    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 python benchmarks/membrane_nonlinear.py --quick   # L1 only, 25x13 speed

Models since the model-layer refactor (docs/architecture.md): the full-order ``FvKMembrane`` and
``BergerMembrane`` (:mod:`wingopt.membrane.full`) share one exponential integrator
(:func:`wingopt.membrane.full.integrate`, which replaces ``simulate_fvk`` and ``simulate_berger``);
the linear reference is the linear forward model (:func:`wingopt.membrane.forward_model`, exact,
which replaces ``simulate_response``); the cubic modal model is :class:`~wingopt.membrane.modal.FvKModal`
with all modes kept (the retired ``CubicModalMembrane(fvk, r)``), integrated by the modal
exact-oscillator predictor-corrector instead of the old exponential-trapezoidal Newton step, so its
``modal`` rows differ from the numbers recorded before the refactor. The full-order models no
longer propagate sensitivities (the old ``berger+sens`` row): the exact tangents live in the modal
models, timed instead (``+tangent`` rows). The tensions are the membrane averages of the mean
stretch, ``BergerMembrane.tensions`` (exact for FvK's average, as before).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time

import numpy as np

from wingopt.fe import load_vector
from wingopt.membrane import bubble, forward_model, load_case
from wingopt.membrane.forward import Reduced
from wingopt.membrane.full import BergerMembrane, FvKMembrane, integrate
from wingopt.membrane.modal import BergerModal, FvKModal
from wingopt.membrane.modal.tangent import ForceTangent
from wingopt.problem import load_problem
from wingopt.workflows.protocols import simulate_case

LOADS = ("L1", "L2", "L3", "LE")
AMPLITUDES = (50.0, 100.0, 200.0, 400.0)
QUICK = {"on": False}
"""``--quick``: L1 only (static at 200 Pa), speed on 25x13 only."""


def _loads():
    return LOADS[:1] if QUICK["on"] else LOADS


def _centre(model, z):
    p = model.problem
    return float(model.space.evaluate(z, np.array([p.width / 2]), np.array([p.height / 2]))[0])


def _tensions(berger: BergerMembrane, Z: np.ndarray) -> np.ndarray:
    """``(N+1, 2)`` membrane-average tensions ``Tx, Ty`` (N/m) of the mean stretch of each deflection."""
    return np.array([berger.tensions(z) for z in Z])


def _cubic_modal(lin, r: int, substeps: int = 1) -> FvKModal:
    """The modal FvK model with all modes, FvK's cubic stiffness on the ``r`` lowest."""
    return FvKModal.build(lin, lin.n, substeps=substeps, cubic_modes=r)


def _tangent_run(modal, f: np.ndarray, z0: np.ndarray, t_end: float):
    """Trajectory and exact tangents to (prestrain x, prestrain y, damping) of a modal model."""
    N, m, P = int(round(t_end / modal.dt)), modal.m, 3
    u = modal.modal_force(f)
    forces = np.ascontiguousarray(np.tile(u, (N, 1)))
    par = modal.nominal
    dforces = ForceTangent(np.ones(N + 1), np.zeros((P, m)), np.zeros((N + 1, 0)), 0, u)
    zeros = np.zeros((P, m))
    return modal.simulate_tangent(
        modal.to_modal(z0), np.zeros(m), forces, par.eps0_x, par.eps0_y, par.viscous_scale, zeros, zeros, np.eye(3),
        dforces,
    )  # fmt: skip


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
    for name in _loads():
        for amp in (200.0,) if QUICK["on"] else AMPLITUDES:
            load = load_case(name, problem.width, problem.height, amp)
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
    roms = {r: _cubic_modal(lin, r) for r in (10, 20)}
    average = BergerMembrane(lin)  # the tensions of the mean stretch (gain 1)
    linear = forward_model(lin, "linear")
    print(
        f"{'load':5} {'model':12} {'s max err':>9} {'s rms err':>9} {'s final':>8} {'w final L2':>10} {'∫w final':>9} "
        f"{'Tx range N/m':>14} {'Ty range N/m':>14}   (errors relative to each sensor's peak / to FvK)"
    )
    for name in _loads():
        f = lin.project(load_case(name, problem.width, problem.height))
        ref = integrate(fvk, f, 1.0, z0=z0, substeps=2)
        sref = lin.sensors.outputs(ref.z)
        peak = np.max(np.abs(sref), axis=0)
        runs = []
        for label, kappa in (("berger", 1.0), ("berger k", KAPPA)):
            berger = BergerMembrane(lin, stretch_gain=kappa)
            tb = integrate(berger, f, 1.0, z0=z0, substeps=2)
            runs.append((label, tb.z, lin.sensors.outputs(tb.z), _tensions(berger, tb.z)))
        for r, rom in roms.items():
            for sub in (1, 2):
                tm = Reduced("fvk", dataclasses.replace(rom, substeps=sub)).run(f, 1.0, z0=z0)
                runs.append((f"modal{r} s{sub}", tm.z, tm.outputs, _tensions(average, tm.z)))
        tl = linear.run(f, 1.0, z0=z0)
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
    f = lin.project(load_case("L1", problem.width, problem.height))
    z0 = lin.project(bubble(problem.width, problem.height))
    ref = lin.sensors.outputs(integrate(fvk, f, 0.3, z0=z0, substeps=8).z)
    for s in (1, 2, 4):
        t0 = time.process_time()
        out = lin.sensors.outputs(integrate(fvk, f, 0.3, z0=z0, substeps=s).z)
        print(
            f"substeps {s}: max sensor error {np.max(np.abs(out - ref)) / np.max(np.abs(ref)):.2e} of the peak, "
            f"{time.process_time() - t0:.1f} s CPU"
        )


def section_speed(problem) -> None:
    print("\n== speed: CPU seconds per simulated second (1 kHz, bubble start, L1) ==")
    for nodes in ((25, 13),) if QUICK["on"] else ((25, 13), (49, 25)):
        _speed_on(problem, nodes)


def _speed_on(problem, nodes) -> None:
    fvk = FvKMembrane(problem, nodes)
    lin = fvk.linear
    f = lin.project(load_case("L1", problem.width, problem.height))
    z0 = lin.project(bubble(problem.width, problem.height))
    berger = BergerMembrane(lin)
    t0 = time.process_time()
    roms = {r: _cubic_modal(lin, r) for r in (10, 20)}
    build = time.process_time() - t0
    print(f"{nodes[0]}x{nodes[1]} building the cubic modal models (all modes, r = 10 and 20): {build:.1f} s")
    bmodal = BergerModal.build(lin, lin.n)
    roms[10].record(f, 0.01, z0=z0)  # load the compiled (numba) loops before timing
    _tangent_run(roms[10], f, z0, 0.01)
    for label, run, dur in (
        ("berger", lambda d: integrate(berger, f, d, z0=z0, substeps=1), 1.0),
        ("berger 2 substeps", lambda d: integrate(berger, f, d, z0=z0, substeps=2), 1.0),
        ("berger modal+tangent", lambda d: _tangent_run(bmodal, f, z0, d), 1.0),
        ("modal r10", lambda d: roms[10].record(f, d, z0=z0), 1.0),
        ("modal r20", lambda d: roms[20].record(f, d, z0=z0), 1.0),
        ("modal r20+tangent", lambda d: _tangent_run(roms[20], f, z0, d), 1.0),
        ("fvk 2 substeps", lambda d: integrate(fvk, f, d, z0=z0, substeps=2), 0.2),
    ):
        t0 = time.process_time()
        run(dur)
        print(f"{nodes[0]}x{nodes[1]} {label:20} {(time.process_time() - t0) / dur:7.2f} s per s")


def _write_csv(path: str, meas) -> None:
    head = "t," + ",".join(meas.sensor_names)
    np.savetxt(path, np.column_stack([meas.t, meas.values]), delimiter=",", header=head, comments="", fmt="%.10e")


def section_mhe(problem, tmp: str) -> None:
    from wingopt.workflows.identify import identify

    print("\n== linear MHE (identify --data) on nonlinear records: truth 49x25, estimator 25x13, 1 % noise, seed 0 ==")
    print(
        f"{'load':5} {'truth':7} {'true lift':>9} {'lift':>8} {'lift err':>9} {'band 1s':>8} {'field err':>9} "
        f"{'wall s':>7}  warnings"
    )
    for truth in ("linear", "fvk"):
        for name in ("L1",) if QUICK["on"] else ("L1", "LE"):
            rec = simulate_case(problem, name, 0.01, 0, truth=truth, tell_noise=False)
            path = os.path.join(tmp, f"wingopt_nl_{truth}_{name}.csv")
            _write_csv(path, rec.measurements)
            # the linear MHE, as before the registry's `auto` chose the FvK estimator for measured data
            run = identify(problem, data=path, method="mhe", model="linear")
            ferr = rec.load_error(run.load_field())  # relative L2 over the membrane
            true = rec.true_lift
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
    ap.add_argument("--quick", action="store_true", help="L1 only (static at 200 Pa), speed on 25x13 only")
    args = ap.parse_args()
    QUICK["on"] = args.quick
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
