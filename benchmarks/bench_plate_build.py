"""Wall time of the plate model on the seed's three meshes: assembly, modes, damped eigenvalues.

    python benchmarks/bench_plate_build.py [--repeat 3]

Prints one line per mesh (best of ``--repeat``); the machine is shared, so take the minimum.
"""

from __future__ import annotations

import argparse
import time

from wingopt.plate.model import PlateModel
from wingopt.problem import load_problem


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    problem = load_problem("plate")
    print(f"{'mesh':>8} {'dofs':>6} {'cells':>6} {'build s':>8} {'4 modes s':>10} {'4 eigs s':>9}")
    for nodes in [(7, 31), (13, 61), (25, 121)]:
        best = [float("inf")] * 3
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            model = PlateModel.from_problem(problem, nodes)
            t1 = time.perf_counter()
            model.frequencies_hz(4)
            t2 = time.perf_counter()
            model.eigenvalues(4)
            t3 = time.perf_counter()
            best = [min(b, t) for b, t in zip(best, (t1 - t0, t2 - t1, t3 - t2))]
        cells = len(model.properties.cells)
        print(f"{nodes[0]:>3}x{nodes[1]:<4} {model.n:>6} {cells:>6} {best[0]:>8.2f} {best[1]:>10.2f} {best[2]:>9.2f}")


if __name__ == "__main__":
    main()
