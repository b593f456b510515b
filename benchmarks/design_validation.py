"""Validation of the sensor design by identification (issue 13 Must-show), all measured in one run.

1. ``heldout`` — K = 4 designed (criterion ``risk``) vs the problem's default layout on held-out
   loads L1, L2, L3, a leading-edge load, the consistency rectangle and 5 smooth random draws (a GP
   family with another length scale and seeds than the design's), ``--heldout-seeds`` noise seeds:
   mean field error ratio and the lift error per load; the designed layout's rank among
   ``--random`` random layouts by the criterion.
2. ``rank`` — ``--layouts`` random 4-sensor layouts (non-overlapping, the default sensor sizes),
   each measured by the MHE on 5 held-out loads (L2, L3, leading edge, rectangle, a smooth draw)
   x ``--seeds`` seeds; Spearman rank correlation of
   the predictions (risk, plain A, D) with the measured mean error.
3. ``curve`` — accuracy vs K (4, 6, 8, 12, 32): designed vs a regular grid vs random layouts, the
   grid's sensor size for every K.

Truth on ``--truth`` (default 49x25), estimator on the problem's 25x13, ``--t-end`` s records (0.3 s:
the errors of L1/L3/consistency agree with 1 s to 0.0004/0.002/0.008, checked once). Every
identification is one :class:`~wingopt.design.montecarlo.IdentifyTask` mapped by a process pool
(``--workers``); results are appended to ``--out`` (JSON) as each part ends.

Run: ``PYTHONPATH=. OMP_NUM_THREADS=1 nice python benchmarks/design_validation.py --out runs/design_validation.json``
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import time
from pathlib import Path

import numpy as np
import scipy.stats as st

from wingopt.design import DesignSettings, InformationSettings, design_sensors
from wingopt.design.criteria import LinearCriterion
from wingopt.design.montecarlo import IdentifyTask, run_task
from wingopt.design.selection import random_layouts
from wingopt.problem import load_problem, parse_mesh
from wingopt.workflows.studies import sensor_grid

HELDOUT = ["L1", "L2", "L3", "leading-edge", "consistency"] + [f"smooth:1000:{k}" for k in range(5)]
RANK_LOADS = ["L2", "L3", "leading-edge", "consistency", "smooth:1000:0"]
GRIDS = {4: (2, 2), 6: (3, 2), 8: (4, 2), 12: (4, 3), 32: (8, 4)}


def measure(problem, layouts: dict, loads, seeds, args, pool) -> dict:
    """Mean errors per layout name: ``{name: {"load_error": {load: mean}, "lift_error": ..., "runs": [...]}}``."""
    tasks = []
    for load in loads:  # grouped by load: each worker simulates a truth once
        for name, rects in layouts.items():
            for seed in seeds:
                tasks.append(
                    IdentifyTask(
                        problem,
                        tuple(tuple(float(v) for v in r) for r in rects),
                        load,
                        args.noise,
                        seed,
                        parse_mesh(args.truth),
                        None,
                        args.t_end,
                        name,
                    )
                )
    t0 = time.perf_counter()
    out: dict = {name: {"runs": []} for name in layouts}
    mapper = pool.imap if pool is not None else map
    for i, rec in enumerate(mapper(run_task, tasks)):
        out[rec["tag"]]["runs"].append(rec)
        if (i + 1) % 50 == 0 or i + 1 == len(tasks):
            print(f"  {i + 1}/{len(tasks)} identifications, {time.perf_counter() - t0:.0f} s", flush=True)
    for d in out.values():
        runs = d["runs"]
        d["load_error"] = {L: float(np.mean([r["load_error"] for r in runs if r["load"] == L])) for L in loads}
        d["lift_error"] = {L: float(np.mean([r["lift_error"] for r in runs if r["load"] == L])) for L in loads}
        d["mean_load_error"] = float(np.mean([r["load_error"] for r in runs]))
        d["run_s"] = float(np.mean([r["wall_s"] for r in runs]))
    return out


def run_curve(problem, args, info, rng, pool, results, save) -> None:
    """Accuracy vs K: designed (risk, coarser grid) vs the regular grid vs random layouts."""
    curve = []
    for K in (int(k) for k in args.ks.split(",")):
        nx, ny = GRIDS[K]
        grid = sensor_grid(problem, nx, ny)
        w, h = grid[0].rect[1] - grid[0].rect[0], grid[0].rect[3] - grid[0].rect[2]
        prob_k = problem.with_sensors(grid)
        t1 = time.perf_counter()
        dk = design_sensors(
            prob_k,
            K,
            f"sizes={w}x{h};step={args.curve_step}",
            DesignSettings(information=info, swap_passes=1, nominal_count=args.curve_nominal),
        )
        tk = time.perf_counter() - t1
        pool_k = np.flatnonzero(dk.candidates.size_index >= 0)
        rl = random_layouts(dk.candidates.rects, K, args.curve_random, rng, pool_k)
        gidx = np.array(dk.baselines["problem_layout"]["layout"])
        lay = {"designed": dk.rects, "grid": dk.candidates.rects[gidx]}
        lay.update({f"random{i}": dk.candidates.rects[r] for i, r in enumerate(rl)})
        print(f"curve K={K}: designed in {tk:.0f} s", flush=True)
        m = measure(problem, lay, RANK_LOADS, range(args.curve_seeds), args, pool)
        row = {
            "K": K,
            "size": [w, h],
            "design_s": tk,
            "designed": m["designed"]["mean_load_error"],
            "grid": m["grid"]["mean_load_error"],
            "random": float(np.mean([m[f"random{i}"]["mean_load_error"] for i in range(len(rl))])),
            "predicted": {
                "designed": dk.value,
                "grid": float(dk.risk.value(gidx)),
                "random": float(np.mean([dk.risk.value(r) for r in rl])),
            },
            "per_load": {k: v["load_error"] for k, v in m.items()},
            "rects": dk.rects.tolist(),
        }
        curve.append(row)
        print(
            f"  K={K}: designed {row['designed']:.3f}, grid {row['grid']:.3f}, random {row['random']:.3f}",
            flush=True,
        )
        results["curve"] = curve
        save()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default="heldout,rank,curve")
    ap.add_argument("--layouts", type=int, default=50)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--heldout-seeds", type=int, default=5)
    ap.add_argument("--random", type=int, default=200)
    ap.add_argument("--ks", default="4,6,8,12,32")
    ap.add_argument("--curve-seeds", type=int, default=2)
    ap.add_argument("--curve-random", type=int, default=2)
    ap.add_argument("--curve-step", type=int, default=4, help="candidate grid step of the curve's designs")
    ap.add_argument("--curve-nominal", type=int, default=6, help="nominal loads of the curve's designs")
    ap.add_argument("--noise", type=float, default=0.01)
    ap.add_argument("--t-end", type=float, default=0.3)
    ap.add_argument("--truth", default="49x25")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="design_validation.json")
    ap.add_argument("--smoke", action="store_true", help="2 loads only (a check that the script runs)")
    ap.add_argument("--rank-loads", help="comma-separated loads of the rank part (default: 5 held-out loads)")
    args = ap.parse_args()
    if args.smoke:
        HELDOUT[:] = ["L1", "smooth:1000:0"]
        RANK_LOADS[:] = ["L1", "smooth:1000:0"]
    if args.rank_loads:
        RANK_LOADS[:] = args.rank_loads.split(",")
    parts = args.parts.split(",")
    problem = load_problem("membrane")
    out_path = Path(args.out)
    results: dict = json.loads(out_path.read_text()) if out_path.exists() else {}
    results["settings"] = vars(args)

    def save():
        out_path.parent.mkdir(parents=True, exist_ok=True)
        out_path.write_text(json.dumps(results, indent=1, default=float))

    pool = mp.get_context("fork").Pool(args.workers) if args.workers > 1 else None
    info = InformationSettings(t_end=args.t_end, noise_fraction=args.noise)
    t0 = time.perf_counter()
    if parts == ["curve"]:
        run_curve(problem, args, info, np.random.default_rng(2027), pool, results, save)
        return
    reuse = "design4" in results and "heldout" not in parts
    # With a design in --out already, only the criteria are rebuilt (no swaps) and its layout reused.
    design = design_sensors(problem, 4, "step=2", DesignSettings(information=info, swap_passes=0 if reuse else 20))
    print(f"  stages: {design.timings}", flush=True)
    t_design = time.perf_counter() - t0
    cands = design.candidates
    default_idx = np.array(design.baselines["problem_layout"]["layout"])
    if reuse:
        idx = np.array([cands.find(r) for r in results["design4"]["rects"]])
        design.layout = idx
        design.value = float(design.risk.value(idx))
        t_design = results["design4"]["wall_s"]
    print(f"design K=4 in {t_design:.0f} s: {np.round(design.rects, 4).tolist()}", flush=True)
    print(f"  predicted risk {design.value:.4f}, default {design.baselines['problem_layout']['value']:.4f}", flush=True)
    if not reuse:
        results["design4"] = {
            "rects": design.rects.tolist(),
            "wall_s": t_design,
            "summary": json.loads(json.dumps(design.summary(), default=float)),
        }
    lin = design.linear
    dcrit = LinearCriterion("d", lin.info, lin.weight, lin.const, lin.scale)
    rng = np.random.default_rng(2026)
    grid_pool = np.flatnonzero(cands.size_index >= 0)

    # the designed layout among random ones, by the criterion
    rand = random_layouts(cands.rects, 4, args.random, rng, grid_pool)
    rv = np.array([design.risk.value(r) for r in rand])
    results["design4"]["rank_among_random_predicted"] = {
        "random": args.random,
        "better_random": int(np.sum(rv < design.value)),
        "percentile": float(100 * np.mean(rv < design.value)),
        "default_better_random": int(np.sum(rv < design.baselines["problem_layout"]["value"])),
    }
    print(f"  designed better than {np.sum(rv >= design.value)}/{args.random} random layouts (criterion)", flush=True)
    save()

    if "heldout" in parts:
        print("held-out check: designed vs default", flush=True)
        lay = {"designed": design.rects, "default": cands.rects[default_idx]}
        m = measure(problem, lay, HELDOUT, range(args.heldout_seeds), args, pool)
        ratio = m["designed"]["mean_load_error"] / m["default"]["mean_load_error"]
        worse_lift = [L for L in HELDOUT if m["designed"]["lift_error"][L] > m["default"]["lift_error"][L]]
        results["heldout"] = {
            "loads": HELDOUT,
            "seeds": args.heldout_seeds,
            "designed": {k: v for k, v in m["designed"].items() if k != "runs"},
            "default": {k: v for k, v in m["default"].items() if k != "runs"},
            "ratio_mean_field_error": ratio,
            "lift_worse_on": worse_lift,
        }
        print(f"  mean field error ratio designed/default {ratio:.3f}; lift worse on {worse_lift}", flush=True)
        save()

    if "rank" in parts:
        print(
            f"rank correlation: {args.layouts} random layouts x {len(RANK_LOADS)} loads x {args.seeds} seeds",
            flush=True,
        )
        lays = rand[: args.layouts]
        m = measure(problem, {i: cands.rects[r] for i, r in enumerate(lays)}, RANK_LOADS, range(args.seeds), args, pool)
        meas = np.array([m[i]["mean_load_error"] for i in range(len(lays))])
        preds = {
            "risk": np.array([design.risk.value(r) for r in lays]),
            "a": np.array([lin.value(r) for r in lays]),
            "d": np.array([dcrit.value(r) for r in lays]),
        }
        rho = {k: float(st.spearmanr(v, meas)[0]) for k, v in preds.items()}
        results["rank"] = {
            "layouts": [cands.rects[r].tolist() for r in lays],
            "measured": meas.tolist(),
            "predicted": {k: v.tolist() for k, v in preds.items()},
            "spearman": rho,
            "run_s": float(np.mean([m[i]["run_s"] for i in range(len(lays))])),
        }
        if "heldout" in results:
            dm = np.mean([results["heldout"]["designed"]["load_error"][L] for L in RANK_LOADS])
            df = np.mean([results["heldout"]["default"]["load_error"][L] for L in RANK_LOADS])
            results["rank"]["designed_measured_rank"] = int(np.sum(meas < dm))
            results["rank"]["default_measured_rank"] = int(np.sum(meas < df))
            results["rank"]["predicted_designed"] = design.value
        print(f"  Spearman vs measured: {rho}", flush=True)
        save()

    if "curve" in parts:
        run_curve(problem, args, info, rng, pool, results, save)
    if pool is not None:
        pool.close()
    print(f"total {time.perf_counter() - t0:.0f} s", flush=True)


if __name__ == "__main__":
    main()
