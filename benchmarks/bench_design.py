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
    ap.add_argument("--rest-stride", type=int, default=4, help="samples after the first window (1: all)")
    args = ap.parse_args()
    problem = load_problem("membrane")
    t0, c0 = time.perf_counter(), time.process_time()
    info = InformationSettings(t_end=args.t_end, rest_stride=args.rest_stride)
    res = design_sensors(
        problem, args.count, f"step={args.step}", DesignSettings(criterion=args.criterion, information=info)
    )
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
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
    print(f"design time {wall:.1f} s wall, {cpu:.1f} s CPU (target <= 60 s): {'met' if cpu <= 60 else 'NOT met'} (CPU)")
    if args.rest_stride > 1:
        # the stride's effect on the chosen layout's criterion: recompute with every sample
        exact = design_sensors(
            problem,
            args.count,
            "only-rects;" + ";".join("rect=" + ":".join(f"{v:.9g}" for v in r) for r in res.rects),
            DesignSettings(criterion=args.criterion, information=InformationSettings(t_end=args.t_end)),
        )
        print(
            f"chosen layout, every sample: {exact.linear.value(list(range(args.count))):.4f} vs stride: {res.value:.4f}"
        )


if __name__ == "__main__":
    main()
