"""``wingopt gains``: full-order continuous LQR gains on several meshes and their functional gains.

The seed's evidence that the control law converges (eq. 5.29, Figs. 5.12–5.17): the feedback gain
of each mesh mapped back to fields, plotted for PZ1, PZ4 and PZ7 along the mid-chord line. The
gains come from Newton–Kleinman with low-rank ADI (:mod:`wingopt.control.riccati_large`).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from wingopt.errors import InputError
from wingopt.results import to_jsonable

ORDER = 25

EXAMPLE = """examples:
  wingopt gains plate --out runs/gains                                  # 7x31, 13x61, 25x121
  wingopt gains plate --meshes 7x31,13x61 --out runs/gains-small --json
  wingopt gains plate --cache runs/gain-cache --out runs/gains          # reuse computed gains

The 25x121 gain takes minutes on a 2-core machine (see docs/control_lqr.md); --cache keeps each
mesh's gain (gains_<mesh>.npz) so that plots can be redrawn without recomputing it."""


def register(sub, common) -> None:
    p = sub.add_parser(
        "gains",
        parents=[common],
        help="full-order LQR gains on several meshes and the convergence of their functional gains",
        description="Compute the continuous full-order LQR gain of the plate on each mesh (Newton-Kleinman with "
        "low-rank ADI) and plot the functional gains of eq. 5.29 for PZ1, PZ4 and PZ7 along x = W/2.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("problem", help="problem file (.toml) or built-in name (plate)")
    p.add_argument("--meshes", default="7x31,13x61,25x121", help="comma-separated meshes (default the seed's three)")
    p.add_argument("--r", type=float, help="input weight R = r I, V^-2 (default 1e-10)")
    p.add_argument("--weight-modes", type=int, help="modes in the state weight (default 20)")
    p.add_argument("--cache", help="directory to keep/reuse gains_<mesh>.npz")
    p.add_argument("--out", required=True, help="output directory (replaced atomically)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    p.set_defaults(func=run)


def run(args) -> int:
    from wingopt.control.riccati_large import DEFAULT_WEIGHT_MODES, GAIN_R, gain_profiles, plate_lqr_gain
    from wingopt.plate import PlateModel
    from wingopt.plots.morph import plot_functional_gains
    from wingopt.problem import load_problem, parse_mesh
    from wingopt.results import ResultDirectory, write_csv, write_json
    from wingopt.results.writer import check_writable

    check_writable(args.out)
    r = GAIN_R if args.r is None else args.r
    wm = DEFAULT_WEIGHT_MODES if args.weight_modes is None else args.weight_modes
    if not (np.isfinite(r) and r > 0):
        raise InputError(f"r = {r!r}: expected a positive input weight")
    if wm < 1:
        raise InputError(f"weight-modes = {wm!r}: expected a positive number of modes")
    meshes = [parse_mesh(t) for t in args.meshes.split(",") if t.strip()]
    if not meshes:
        raise InputError("meshes: expected at least one mesh, e.g. 7x31,13x61")
    problem = load_problem(args.problem)
    if problem.kind != "plate":
        raise InputError(f"problem = {args.problem!r}: gains needs a plate problem, got kind {problem.kind!r}")
    cache = Path(args.cache) if args.cache else None
    records, profiles = [], {}
    for nodes in meshes:
        label = f"{nodes[0]}x{nodes[1]}"
        model = PlateModel.from_problem(problem, nodes)
        rec = {"mesh": label, "dofs": model.n, "states": 2 * model.n}
        hit = cache / f"gains_{label}.npz" if cache else None
        if hit is not None and hit.exists():
            data = np.load(hit)
            if float(data["r"]) == r and int(data["weight_modes"]) == wm and data["K"].shape[1] == 2 * model.n:
                K = data["K"]
                rec.update(json.loads(str(data["info"])) if "info" in data.files else {}, cached=True)
            else:
                K = None
        else:
            K = None
        if K is None:
            t0 = time.perf_counter()
            K, info = plate_lqr_gain(model, r, weight_modes=wm)
            rec.update({k: v for k, v in info.items()}, wall_s=time.perf_counter() - t0)
            if cache is not None:
                cache.mkdir(parents=True, exist_ok=True)
                np.savez(cache / f"gains_{label}.npz", K=K, r=r, weight_modes=wm, info=json.dumps(to_jsonable(rec)))
        profiles[label] = gain_profiles(model, K)
        records.append(rec)
    summary = {"problem": problem.name, "r": r, "weight_modes": wm, "meshes": records}
    with ResultDirectory(args.out) as tmp:
        write_json(tmp / "summary.json", summary)
        header, cols = ["y"], [profiles[records[0]["mesh"]]["y"]]
        for lab, pr in profiles.items():
            for j, name in enumerate(pr["patches"]):
                header += [f"bending_{name}_{lab}", f"velocity_{name}_{lab}"]
                cols += [pr["bending"][j], pr["velocity"][j]]
        write_csv(tmp / "profiles.csv", header, np.column_stack(cols))
        plot_functional_gains(tmp / "functional_gains.png", profiles)
    if args.json:
        print(json.dumps(to_jsonable(summary)))
    else:
        for rec in records:
            how = "cached" if rec.get("cached") else f"{rec.get('total_s', 0):.1f} s"
            print(f"{rec['mesh']:>7}: {rec['states']} states, {rec.get('newton_steps')} Newton steps, {how}")
        print(f"-> {args.out}")
    return 0
