"""Does a design criterion rank layouts like the estimator's measured error? (issue 13 Must-show 1)

``--layouts`` random 4-sensor layouts (non-overlapping, the problem's sensor sizes, drawn from the
step-2 candidate grid with ``--layout-seed``), each identified by the MHE (truth ``--truth``,
estimator 25x13, 1 % noise, ``--t-end`` s records) on the held-out loads ``--loads`` x ``--seeds``
noise seeds; the measured error of a layout is its mean relative load error over all of them.
The same layouts are scored by the linearised criteria (``risk``, plain A, D; the settings of
``wingopt design-sensors``) and by the Monte Carlo criterion: the mean error of the same estimator
on the *design-time* loads ``--mc-loads`` (draws of the design's own nominal family, GP length 0.2
chord, seed 7; none of them held out) x ``--mc-seeds`` noise seeds (seeds 100.., not the held-out
ones). Prints the Spearman rank correlation of each prediction with the measured error.

Every identification is one task of the study engine (:mod:`wingopt.workflows.sweep`, the engine of
``wingopt compare``), ``--workers`` local worker processes; each record is appended to
``OUT/records.jsonl`` as it finishes (``--resume`` runs only the missing ones), the result goes to
``OUT/summary.json``.

Run: ``PYTHONPATH=. OMP_NUM_THREADS=1 nice -n 10 python benchmarks/design_rank.py --out runs/design_rank``
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import scipy.stats as st

from wingopt.design import DesignSettings, InformationSettings
from wingopt.design.candidates import parse_candidates, with_problem_sensors
from wingopt.design.criteria import LinearCriterion
from wingopt.design.engine import nominal_loads
from wingopt.design.information import ModalSensitivity
from wingopt.design.montecarlo import IdentifyTask, run_task
from wingopt.design.priors import gp_prior, smooth_loads
from wingopt.design.risk import BayesRisk
from wingopt.design.selection import random_layouts
from wingopt.membrane import MembraneModel
from wingopt.problem import load_problem, parse_mesh
from wingopt.workflows.sweep.engine import Engine, EngineSettings, SweepTask

HELDOUT = "L1,L2,L3,leading-edge,consistency,smooth:1000:0,smooth:1000:1,smooth:1000:2"
MC_LOADS = "smooth:7:0:0.2,smooth:7:1:0.2,smooth:7:2:0.2,smooth:7:3:0.2"
BROAD_LOADS = "smooth:8:0:0.1,smooth:8:1:0.1"
"""Localised design-time loads (GP length 0.1 chord, seed 8) that broaden the Monte Carlo prior."""


def criteria(problem, spec: str, info: InformationSettings):
    """Candidates and the linearised criteria (risk, A, D) of ``design_sensors``' defaults, no selection."""
    s = DesignSettings(information=info)
    cands, default_idx = with_problem_sensors(problem, parse_candidates(spec, problem, info.sub))
    model = MembraneModel.from_problem(problem.with_sensors(()))
    sens = ModalSensitivity.from_model(model, info)
    chat = sens.modal_matrices(cands.rects)
    q0 = sens.initial_state()
    loads = nominal_loads(problem, s)
    infos = [sens.information(chat, sens.modal_load(model.project(P)), q0) for P in loads]
    risk = BayesRisk.build(sens, infos, loads, q0)
    # the same risk over a broadened family: the 12 draws plus 6 localised ones (length 0.1 chord)
    loc = smooth_loads(problem.width, problem.height, 6, 8, 0.1 * problem.width)
    infos_b = infos + [sens.information(chat, sens.modal_load(model.project(P)), q0) for P in loc]
    risk_b = BayesRisk.build(sens, infos_b, loads + loc, q0)
    prior = gp_prior(model, 0.2 * problem.width, abs(problem.identification.initial_load))
    lin4 = infos[:4]  # the linear criteria's default family: the first 4 nominal loads
    a = LinearCriterion.build("a", sens, lin4, prior, q0)
    d = LinearCriterion.build("d", sens, lin4, prior, q0)
    return cands, default_idx, {"risk": risk.value, "risk-broad": risk_b.value, "a": a.value, "d": d.value}


def measure(problem, layouts: dict, runs: list[tuple[str, int]], args, out: Path) -> list[dict]:
    """Run (or resume) every (layout, (load, seed)) identification on the study engine."""
    rec_path = out / "records.jsonl"
    done = {}
    if rec_path.exists() and args.resume:
        for line in rec_path.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                if r.get("status") == "ok":
                    done[r["key"]] = r
    tasks = []
    for name, rects in layouts.items():  # layout-major: a worker reuses each layout's model
        rr = tuple(tuple(float(v) for v in r) for r in rects)
        for load, seed in runs:
            key = f"{name}|{load}|{seed}"
            if key not in done:
                t = IdentifyTask(problem, rr, load, args.noise, seed, parse_mesh(args.truth), None, args.t_end, name)
                tasks.append(SweepTask(key, run_task, (t,)))
    print(f"  {len(tasks)} identifications to run ({len(done)} recorded)", flush=True)
    t0 = time.perf_counter()
    mode = "serial" if args.workers == 1 else "local"
    with (
        Engine(EngineSettings(mode=mode, workers=args.workers, progress=False, dashboard=False)) as eng,
        open(rec_path, "a") as fh,
    ):
        for i, rec in enumerate(eng.run(tasks)):
            fh.write(json.dumps(rec, default=float) + "\n")
            fh.flush()
            if rec.get("status") == "ok":
                done[rec["key"]] = rec
            if (i + 1) % 50 == 0 or i + 1 == len(tasks):
                print(f"  {i + 1}/{len(tasks)}, {time.perf_counter() - t0:.0f} s", flush=True)
    return list(done.values())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layouts", type=int, default=50)
    ap.add_argument("--layout-seed", type=int, default=4242, help="seed of the random layouts (not used before)")
    ap.add_argument("--loads", default=HELDOUT, help="held-out loads (comma-separated)")
    ap.add_argument("--seeds", type=int, default=3, help="noise seeds per held-out load (0..)")
    ap.add_argument("--mc-loads", default=MC_LOADS, help="design-time loads of the Monte Carlo criterion")
    ap.add_argument("--broad-loads", default=BROAD_LOADS, help="extra (localised) loads of the broadened MC")
    ap.add_argument("--edge-loads", default="", help="edge-heavy loads (edge:SEED:K) of an edge-aware MC variant")
    ap.add_argument("--mc-seeds", type=int, default=1, help="noise seeds of the Monte Carlo criterion (100..)")
    ap.add_argument("--noise", type=float, default=0.01)
    ap.add_argument("--t-end", type=float, default=0.3)
    ap.add_argument("--truth", default="49x25")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="runs/design_rank")
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--with-default", action="store_true", help="also measure the problem's own layout")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    problem = load_problem("membrane")
    c0, t0 = time.process_time(), time.perf_counter()
    cands, default_idx, crit = criteria(
        problem, "step=2", InformationSettings(t_end=args.t_end, noise_fraction=args.noise)
    )
    t_crit = time.process_time() - c0
    pool = np.flatnonzero(cands.size_index >= 0)
    lays = random_layouts(cands.rects, 4, args.layouts, np.random.default_rng(args.layout_seed), pool)
    print(f"{len(cands)} candidates, criteria in {t_crit:.0f} s CPU; {len(lays)} layouts", flush=True)
    layouts = {f"r{i}": cands.rects[r] for i, r in enumerate(lays)}
    if args.with_default:  # the problem's layout, measured alike (not one of the ranked layouts)
        layouts["default"] = cands.rects[default_idx]
    held, mc = args.loads.split(","), args.mc_loads.split(",")
    broad = [L for L in args.broad_loads.split(",") if L]
    edge = [L for L in args.edge_loads.split(",") if L]
    runs = [(L, s) for L in held for s in range(args.seeds)]
    runs += [(L, s) for L in mc + broad + edge for s in range(100, 100 + args.mc_seeds)]
    recs = measure(problem, layouts, runs, args, out)

    def mean_err(name, loads):
        v = [r["load_error"] for r in recs if r["tag"] == name and r["load"] in loads]
        return float(np.mean(v)) if v else float("nan")

    names = [n for n in layouts if n != "default"]
    meas = np.array([mean_err(n, held) for n in names])
    preds = {k: np.array([f(r) for r in lays]) for k, f in crit.items()}
    preds["montecarlo"] = np.array([mean_err(n, mc) for n in names])
    if broad:
        preds["montecarlo-broad"] = np.array([mean_err(n, mc + broad) for n in names])
    if edge:
        preds["montecarlo-edge"] = np.array([mean_err(n, mc + edge) for n in names])
    rho = {k: float(st.spearmanr(v, meas)[0]) for k, v in preds.items()}
    per_load = {L: [mean_err(n, [L]) for n in names] for L in held}
    rho_load = {k: {L: float(st.spearmanr(v, per_load[L])[0]) for L in held} for k, v in preds.items()}
    cpu = [r["cpu_s"] for r in recs if "cpu_s" in r]
    summary = {
        "settings": vars(args),
        "candidates": len(cands),
        "criteria_cpu_s": t_crit,
        "layouts": {n: layouts[n].tolist() for n in names},
        "measured": meas.tolist(),
        "measured_range": [float(meas.min()), float(meas.max())],
        "default_measured": mean_err("default", held) if args.with_default else None,
        "default_per_load": {L: mean_err("default", [L]) for L in held} if args.with_default else None,
        "per_load": per_load,
        "predicted": {k: v.tolist() for k, v in preds.items()},
        "spearman": rho,
        "spearman_per_load": rho_load,
        "identifications": len(recs),
        "cpu_per_identification_s": float(np.mean(cpu)) if cpu else None,
        "wall_s": time.perf_counter() - t0,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(f"measured mean error over {len(held)} loads x {args.seeds} seeds: {meas.min():.3f}..{meas.max():.3f}")
    if args.with_default:
        dm = summary["default_measured"]
        print(
            f"default layout {dm:.3f}; best random / default {meas.min() / dm:.3f}; random better: {np.sum(meas < dm)}"
        )
    for k, v in rho.items():
        print(f"  Spearman {k:>10s}: {v:.3f}")
    print(f"CPU per identification {summary['cpu_per_identification_s']:.2f} s; wall {summary['wall_s']:.0f} s")


if __name__ == "__main__":
    main()
