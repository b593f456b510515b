"""Peak memory of ``wingopt design-sensors membrane --count 4`` (issue 33: 5.6 GB before, <= 1.5 GB).

Run: ``PYTHONPATH=. OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_design_memory.py
[--count 4] [--candidates SPEC] [--criterion risk]``

Runs the command's design (default: the default membrane and candidates, 2331 of them, 12 nominal
loads, criterion risk) with its stage lines on stderr, then prints the chosen layout, the size of
the packed candidate information (:mod:`wingopt.design.stack`), the CPU and wall time and the peak
resident memory of the process (``ru_maxrss``, as ``/usr/bin/time -v`` reports it). A smaller
case (``--candidates step=3``: 270 candidates) scales the same way: the information is
``candidates x nominal loads x 2 x d (d + 1) / 2`` numbers (d = 64).
"""

from __future__ import annotations

import argparse
import logging
import resource
import sys
import time

from wingopt.problem import load_problem
from wingopt.workflows.design import design_layout, design_settings


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=4)
    ap.add_argument("--candidates", default=None, help="a --candidates SPEC (default: the command's)")
    ap.add_argument("--criterion", default="risk", choices=("risk", "a", "lift", "d"))
    ap.add_argument(
        "--swap-passes", type=int, default=20, help="0: no swaps (their memory is greedy's: chunked evaluations)"
    )
    args = ap.parse_args()
    logging.basicConfig(stream=sys.stderr, format="%(message)s")
    logging.getLogger("wingopt.progress").setLevel(logging.INFO)
    problem = load_problem("membrane")
    t0, c0 = time.perf_counter(), time.process_time()
    res = design_layout(
        problem,
        args.count,
        args.candidates,
        design_settings(criterion=args.criterion, swap_passes=args.swap_passes),
        progress=True,
    )
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # kB on Linux
    n, J = len(res.candidates), len(res.nominal_loads)
    d = res.sensitivity.dim
    packed = n * J * 2 * d * (d + 1) // 2 * 8 / 2**20
    print(f"candidates {n} x nominal loads {J} (d = {d}): packed information {packed:.0f} MB")
    print(f"layout {sorted(int(i) for i in res.layout)}, {res.settings.criterion} {res.value:.6f}")
    print(f"CPU {cpu:.0f} s, wall {wall:.0f} s, peak memory (max RSS) {peak:.0f} MB")


if __name__ == "__main__":
    main()
