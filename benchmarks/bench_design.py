"""Design time of the linearised criterion: >= 1,000 candidates on the 25x13 membrane (issue 13: <= 60 s).

Run: ``PYTHONPATH=. OMP_NUM_THREADS=1 python benchmarks/bench_design.py [--count 4] [--step 1] [--criterion a]``
Prints the candidate count, the time of each stage and the relaxation bound and gap.
"""

from __future__ import annotations

import argparse
import time

from wingopt.design import DesignSettings, InformationSettings, design_sensors
from wingopt.problem import load_problem


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=4)
    ap.add_argument("--step", type=int, default=1, help="candidate grid step in lattice cells (1: ~2,000)")
    ap.add_argument("--criterion", default="a", choices=("a", "lift", "d", "risk"))
    ap.add_argument("--t-end", type=float, default=1.0)
    args = ap.parse_args()
    problem = load_problem("membrane")
    t0 = time.perf_counter()
    res = design_sensors(
        problem,
        args.count,
        f"step={args.step}",
        DesignSettings(criterion=args.criterion, information=InformationSettings(t_end=args.t_end)),
    )
    wall = time.perf_counter() - t0
    rel = res.relaxation
    print(f"candidates: {len(res.candidates)} (25x13, {problem.identification.dt * 1e3:g} ms, {args.t_end:g} s record)")
    print(f"criterion {args.criterion}, K = {args.count}: value {res.value:.4f}")
    print("stages (s): " + ", ".join(f"{k} {v:.1f}" for k, v in res.timings.items()))
    print(
        f"relaxation ({rel['solver']}, rank {rel['rank']}): bound {rel['bound']:.4f}, chosen (reduced) "
        f"{rel['chosen_reduced']:.4f}, gap {rel['gap']:.4f} ({100 * rel['relative_gap']:.0f} %)"
    )
    base = res.baselines
    print(f"greedy {base['greedy']['value']:.4f}, rounded relaxation {base['relaxation_rounded']['value']:.4f}")
    print(f"design time {wall:.1f} s (target <= 60 s): {'met' if wall <= 60 else 'NOT met'}")


if __name__ == "__main__":
    main()
