"""K = 4 designed layouts against the problem's default layout on held-out loads (issue 13 Must-show 2).

1. design: ``design_sensors`` (criterion ``risk``, the problem's sensor sizes on the step-2 grid,
   ``--t-end`` s records, 1 % noise), then the Monte Carlo re-ranking of its short list
   (:mod:`wingopt.design.rerank`: ``--shortlist`` layouts through the MHE on the design's own
   nominal loads ``smooth:7:K:0.2``, K = 0..3, noise seeds 100, 101; no held-out load);
2. each layout's rank among ``--random`` random layouts of the same sizes, by the criterion;
3. held-out check: the risk design, the re-ranked design and the default layout, identified on
   L1, L2, L3, the leading-edge load, the consistency rectangle and five draws of another GP family
   (length 0.3 chord, seed 1000), ``--seeds`` noise seeds each (truth 49x25, estimator 25x13):
   mean field error ratio to the default and the lift error per load.

Every identification is a task of the study engine (:mod:`wingopt.workflows.sweep`), ``--workers``
local workers. Results to ``OUT/summary.json``; CPU times are reported (the machine is shared).

Run: ``PYTHONPATH=. OMP_NUM_THREADS=1 nice -n 10 python benchmarks/design_heldout.py --out runs/design_heldout``
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from wingopt.design import DesignSettings, InformationSettings, design_sensors
from wingopt.design.montecarlo import IdentifyTask, run_task
from wingopt.design.rerank import MonteCarloSettings, rerank
from wingopt.design.selection import random_layouts
from wingopt.problem import load_problem, parse_mesh
from wingopt.workflows.sweep.engine import Engine, EngineSettings, SweepTask

HELDOUT = ["L1", "L2", "L3", "leading-edge", "consistency"] + [f"smooth:1000:{k}" for k in range(5)]


def engine_mapper(eng: Engine, prefix: str):
    """``mapper(fn, tasks)`` for :func:`wingopt.design.montecarlo.run_tasks` on the study engine."""

    def mapper(fn, tasks):
        return eng.run([SweepTask(f"{prefix}{i}", fn, (t,)) for i, t in enumerate(tasks)])

    return mapper


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--shortlist", type=int, default=8)
    ap.add_argument("--random", type=int, default=200)
    ap.add_argument("--t-end", type=float, default=0.3)
    ap.add_argument("--truth", default="49x25")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--swap-passes", type=int, default=20)
    ap.add_argument("--step", type=int, default=2, help="candidate grid step (lattice cells)")
    ap.add_argument("--out", default="runs/design_heldout")
    ap.add_argument("--smoke", action="store_true", help="a check that the script runs (coarse, 2 loads)")
    args = ap.parse_args()
    if args.smoke:
        HELDOUT[:] = ["L1", "smooth:1000:0"]
        args.seeds, args.shortlist, args.random, args.step, args.swap_passes = 1, 2, 10, 8, 1
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    problem = load_problem("membrane")
    res: dict = {"settings": vars(args)}

    def save():
        (out / "summary.json").write_text(json.dumps(res, indent=1, default=float))

    c0 = time.process_time()
    info = InformationSettings(t_end=args.t_end, noise_fraction=0.01)
    design = design_sensors(
        problem, 4, f"step={args.step}", DesignSettings(information=info, swap_passes=args.swap_passes)
    )
    res["design"] = {
        "cpu_s": time.process_time() - c0,
        "timings_wall_s": design.timings,
        "rects": design.rects.tolist(),
        "risk": design.value,
        "default_risk": design.baselines["problem_layout"]["value"],
        "relaxation": design.relaxation,
    }
    print(f"design in {res['design']['cpu_s']:.0f} s CPU: risk {design.value:.4f}", flush=True)
    save()
    cands = design.candidates
    default_idx = np.array(design.baselines["problem_layout"]["layout"])
    mode = "serial" if args.workers == 1 else "local"
    with Engine(EngineSettings(mode=mode, workers=args.workers, progress=False, dashboard=False)) as eng:
        t0 = time.perf_counter()
        mcs = MonteCarloSettings(shortlist=args.shortlist, t_end=args.t_end, truth_nodes=parse_mesh(args.truth))
        if args.smoke:
            mcs = MonteCarloSettings(("smooth:7:0:0.2",), (100,), 2, t_end=args.t_end, truth_nodes=(25, 13))
        rr = rerank(design, mcs, engine_mapper(eng, "mc"))
        mc_cpu = float(sum(r["cpu_s"] for r in rr.records))
        mc_layout = rr.layouts[rr.best]
        res["rerank"] = rr.summary() | {
            "cpu_s": mc_cpu,
            "wall_s": time.perf_counter() - t0,
            "rects": cands.rects[mc_layout].tolist(),
        }
        print(f"re-ranked: scores {np.round(rr.scores, 4).tolist()}, best #{rr.best}; {mc_cpu:.0f} s CPU", flush=True)
        save()

        rng = np.random.default_rng(2031)
        rand = random_layouts(cands.rects, 4, args.random, rng, np.flatnonzero(cands.size_index >= 0))
        rv = np.array([design.risk.value(r) for r in rand])
        res["rank_among_random_predicted"] = {
            name: {"risk": float(design.risk.value(lay)), "random_better": int(np.sum(rv < design.risk.value(lay)))}
            for name, lay in (("designed", design.layout), ("reranked", mc_layout), ("default", default_idx))
        }
        res["rank_among_random_predicted"]["random"] = args.random
        save()

        layouts = {"designed": design.rects, "reranked": cands.rects[mc_layout], "default": cands.rects[default_idx]}
        if np.array_equal(np.sort(mc_layout), np.sort(design.layout)):
            layouts.pop("reranked")
        tasks = []
        for load in HELDOUT:
            for name, rects in layouts.items():
                rr_ = tuple(tuple(float(v) for v in r) for r in rects)
                for seed in range(args.seeds):
                    t = IdentifyTask(problem, rr_, load, 0.01, seed, parse_mesh(args.truth), None, args.t_end, name)
                    tasks.append(SweepTask(f"{name}|{load}|{seed}", run_task, (t,)))
        recs = [r for r in eng.run(tasks) if r.get("status") == "ok"]
    held: dict = {}
    for name in layouts:
        mine = [r for r in recs if r["tag"] == name]
        held[name] = {
            "load_error": {L: float(np.mean([r["load_error"] for r in mine if r["load"] == L])) for L in HELDOUT},
            "lift_error": {L: float(np.mean([r["lift_error"] for r in mine if r["load"] == L])) for L in HELDOUT},
            "mean_load_error": float(np.mean([r["load_error"] for r in mine])),
            "runs": len(mine),
        }
    for name in layouts:
        if name == "default":
            continue
        d = held[name]
        d["ratio_to_default"] = d["mean_load_error"] / held["default"]["mean_load_error"]
        d["lift_worse_on"] = [L for L in HELDOUT if d["lift_error"][L] > held["default"]["lift_error"][L]]
        print(f"{name}: mean field error ratio {d['ratio_to_default']:.3f}; lift worse on {d['lift_worse_on']}")
    res["heldout"] = held
    res["heldout_cpu_per_identification_s"] = float(np.mean([r["cpu_s"] for r in recs]))
    save()


if __name__ == "__main__":
    main()
