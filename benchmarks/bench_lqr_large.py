"""Full-order continuous LQR gains of the plate: NK-ADI against the dense reference, and timings.

    OMP_NUM_THREADS=1 python benchmarks/bench_lqr_large.py                  # 7x31 and 13x61 vs dense, 25x121
    OMP_NUM_THREADS=1 python benchmarks/bench_lqr_large.py --meshes 7x31 --no-large
    python benchmarks/bench_lqr_large.py --save runs/gains                   # keep the gains (.npz) for plots

For each mesh: model build, NK-ADI gain (Newton steps, ADI shifts per step, LU factorizations,
wall time), and where the dense reference is feasible (up to 13x61: 1830 states) its wall time and
the relative gain error ``||K_adi - K_dense||_F / ||K_dense||_F``. Single-threaded BLAS is the
reliable setting on this shared 2-core machine (threaded BLAS can be many times slower).
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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--meshes", default="7x31,13x61,25x121", help="comma-separated meshes")
    ap.add_argument("--dense-max-dofs", type=int, default=1000, help="dense reference up to this many dofs")
    ap.add_argument("--r", type=float, default=GAIN_R, help=f"input weight (default {GAIN_R:g})")
    ap.add_argument("--weight-modes", type=int, default=DEFAULT_WEIGHT_MODES, help="modes in the state weight")
    ap.add_argument("--no-large", action="store_true", help="skip meshes above the dense limit")
    ap.add_argument("--save", help="directory for gains_<mesh>.npz")
    ap.add_argument("--json", action="store_true", help="print one JSON record per mesh")
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
        K, info = plate_lqr_gain(model, args.r, weight_modes=args.weight_modes)
        rec.update(
            nkadi_s=round(info["total_s"], 1),
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
        if args.save:
            out = Path(args.save)
            out.mkdir(parents=True, exist_ok=True)
            np.savez(out / f"gains_{text}.npz", K=K, nodes=np.array(nodes), r=args.r, weight_modes=args.weight_modes)
        if args.json:
            print(json.dumps(rec))
        else:
            line = (
                f"{text:>7}: {rec['states']:5d} states, NK-ADI {rec['nkadi_s']:7.1f} s "
                f"({rec['newton_steps']} Newton steps, gain changes {rec['gain_changes']}, {rec['stop_reason']}; "
                f"shifts {rec['adi_shifts']}, {rec['factorizations']} LUs)"
            )
            if "dense_s" in rec:
                line += (
                    f"; dense {rec['dense_s']:.1f} s (residual {rec['dense_riccati_residual']:.1e}); "
                    f"gain rel. error {rec['gain_relative_error']:.2e}; "
                    f"dense / NK-ADI time {rec['dense_s'] / rec['nkadi_s']:.2f}"
                )
            else:
                line += f"; seed's 4 h / NK-ADI time {SEED_HOURS * 3600 / rec['nkadi_s']:.0f}x"
            print(line, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
