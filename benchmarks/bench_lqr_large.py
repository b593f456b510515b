"""Full-order continuous LQR gains of the plate: NK-ADI against the dense reference, and timings.

    OMP_NUM_THREADS=1 python benchmarks/bench_lqr_large.py                  # 7x31 and 13x61 vs dense, 25x121
    OMP_NUM_THREADS=1 python benchmarks/bench_lqr_large.py --meshes 25x121 --previous   # + the previous settings
    OMP_NUM_THREADS=1 python benchmarks/bench_lqr_large.py --meshes 7x31 --no-large
    python benchmarks/bench_lqr_large.py --save runs/gains                   # keep the gains (.npz) for plots

For each mesh: model build, NK-ADI gain (Newton steps, ADI shifts per step, LU factorizations,
wall and CPU time), and where the dense reference is feasible (up to 13x61: 1830 states) its time
and the relative gain error ``||K_adi - K_dense||_F / ||K_dense||_F``. For 25x121 the ratio to the
previous solver's 353 s (issue 16) and to the seed's four hours is printed; ``--previous`` also
runs the previous settings (every ADI solve to its residual target or 800 shifts, new projection
shifts in every Newton step) in the same run and prints the gain error and time ratio against it;
``--previous-gain FILE.npz`` compares with a saved gain instead. CPU time is printed beside wall
time because the machine is shared. Single-threaded BLAS is the reliable setting on this shared
2-core machine (threaded BLAS can be many times slower).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from wingopt.control.riccati_large import DEFAULT_WEIGHT_MODES, GAIN_R, gain_relative_error, plate_lqr_gain
from wingopt.plate import PlateModel
from wingopt.problem import load_problem

SEED_HOURS = 4.0
"""What the seed reports for its 25x121 gain (dense Hamiltonian solver)."""

PREVIOUS_25x121_S = 353.4
"""The 25x121 gain before issue 16 (800 shifts per Newton step; docs/control_lqr.md), one core."""

PREVIOUS_SETTINGS = {"gain_tol": 0.0, "reuse_shifts": False}
"""The ADI stopping and shift policy before issue 16."""


def _timed_gain(model, r, weight_modes, **kw):
    t0, c0 = time.perf_counter(), time.process_time()
    K, info = plate_lqr_gain(model, r, weight_modes=weight_modes, **kw)
    return K, info, time.perf_counter() - t0, time.process_time() - c0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--meshes", default="7x31,13x61,25x121", help="comma-separated meshes")
    ap.add_argument("--dense-max-dofs", type=int, default=1000, help="dense reference up to this many dofs")
    ap.add_argument("--r", type=float, default=GAIN_R, help=f"input weight (default {GAIN_R:g})")
    ap.add_argument("--weight-modes", type=int, default=DEFAULT_WEIGHT_MODES, help="modes in the state weight")
    ap.add_argument("--no-large", action="store_true", help="skip meshes above the dense limit")
    ap.add_argument("--save", help="directory for gains_<mesh>.npz")
    ap.add_argument("--json", action="store_true", help="print one JSON record per mesh")
    ap.add_argument("--previous", action="store_true", help="also run the previous (pre-issue-16) ADI settings")
    ap.add_argument("--previous-gain", help="saved gain (.npz with K) to compare with")
    args = ap.parse_args(argv)
    problem = load_problem("plate")
    for text in args.meshes.split(","):
        nodes = tuple(int(v) for v in text.lower().split("x"))
        t0 = time.perf_counter()
        model = PlateModel.from_problem(problem, nodes)
        build = time.perf_counter() - t0
        rec = {"mesh": text, "dofs": model.n, "states": 2 * model.n, "build_s": round(build, 2)}
        if model.n > args.dense_max_dofs and args.no_large:
            continue
        K, info, wall, cpu = _timed_gain(model, args.r, args.weight_modes)
        rec.update(
            nkadi_s=round(wall, 1),
            nkadi_cpu_s=round(cpu, 1),
            initial_gain_s=round(info["initial_gain_s"], 1),
            newton_steps=info["newton_steps"],
            adi_shifts=info["adi_steps"],
            factorizations=info["factorizations"],
            final_gain_change=info["gain_changes"][-1],
            converged=info["converged"],
            stop_reason=info["stop_reason"],
            gain_changes=[float(f"{c:.2e}") for c in info["gain_changes"]],
        )
        if model.n <= args.dense_max_dofs:
            Kd, dinfo = plate_lqr_gain(model, args.r, weight_modes=args.weight_modes, method="dense")
            rec.update(
                dense_s=round(dinfo["total_s"], 1),
                dense_newton_steps=dinfo["newton_steps"],
                dense_riccati_residual=dinfo["riccati_residual"],
                gain_relative_error=gain_relative_error(K, Kd),
            )
        if args.previous:
            Kp, pinfo, pwall, pcpu = _timed_gain(model, args.r, args.weight_modes, **PREVIOUS_SETTINGS)
            rec.update(
                previous_s=round(pwall, 1),
                previous_cpu_s=round(pcpu, 1),
                previous_adi_shifts=pinfo["adi_steps"],
                error_vs_previous=gain_relative_error(K, Kp),
            )
        if args.previous_gain:
            rec["error_vs_saved"] = gain_relative_error(K, np.load(args.previous_gain)["K"])
        if args.save:
            out = Path(args.save)
            out.mkdir(parents=True, exist_ok=True)
            np.savez(out / f"gains_{text}.npz", K=K, nodes=np.array(nodes), r=args.r, weight_modes=args.weight_modes)
        if args.json:
            print(json.dumps(rec))
        else:
            line = (
                f"{text:>7}: {rec['states']:5d} states, NK-ADI {rec['nkadi_s']:7.1f} s wall, "
                f"{rec['nkadi_cpu_s']:.1f} s CPU "
                f"({rec['newton_steps']} Newton steps, gain changes {rec['gain_changes']}, {rec['stop_reason']}; "
                f"shifts {rec['adi_shifts']}, {rec['factorizations']} LUs)"
            )
            if "dense_s" in rec:
                line += (
                    f"; dense {rec['dense_s']:.1f} s (residual {rec['dense_riccati_residual']:.1e}); "
                    f"gain rel. error {rec['gain_relative_error']:.2e}; "
                    f"dense / NK-ADI time {rec['dense_s'] / rec['nkadi_s']:.2f}"
                )
            elif text == "25x121":
                line += (
                    f"; previous 353.4 s / NK-ADI CPU time {PREVIOUS_25x121_S / rec['nkadi_cpu_s']:.1f}x"
                    f" (wall {PREVIOUS_25x121_S / rec['nkadi_s']:.1f}x); "
                    f"seed's 4 h / NK-ADI CPU time {SEED_HOURS * 3600 / rec['nkadi_cpu_s']:.0f}x"
                )
            if "previous_s" in rec:
                line += (
                    f"; previous settings {rec['previous_s']:.1f} s wall, {rec['previous_cpu_s']:.1f} s CPU "
                    f"(shifts {rec['previous_adi_shifts']}), "
                    f"CPU ratio {rec['previous_cpu_s'] / rec['nkadi_cpu_s']:.1f}x, "
                    f"gain error vs previous {rec['error_vs_previous']:.2e}"
                )
            if "error_vs_saved" in rec:
                line += f"; gain error vs {args.previous_gain}: {rec['error_vs_saved']:.2e}"
            print(line, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
