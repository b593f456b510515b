"""Issue 34: the morph QP on plants that are not its model; the QP step's CPU time with disturbance states.

    OMP_NUM_THREADS=1 python benchmarks/bench_morph_robustness.py --timing            # step p99 / period
    OMP_NUM_THREADS=1 python benchmarks/bench_morph_robustness.py --plants 20 --out runs/robust.json

``--timing``: the closed-loop QP on the nominal 13x61 plate, each shape, offset-free on and off,
the CPU time (``time.thread_time``) of every ``step`` (filter, target calculation, QP), p50/p99
over the period. Otherwise: the issue's three plants and ``--plants`` random ones (moduli
0.9-1.1, d33 0.8-1.2, damping 0.5-2 log-uniform, hysteresis 15 %), every shape, the offset-free
QP, today's QP and the saturated LQR; prints the final shape errors against each plant's best and
the per-shape distribution of the relative excess (:func:`excess_table`).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from wingopt.control.closed_loop import simulate_closed_loop
from wingopt.control.mpc import make_qp_controller
from wingopt.plate import PlateModel
from wingopt.plate.shapes import SHAPES
from wingopt.plots.morph import plot_robustness
from wingopt.problem import load_problem, parse_mesh
from wingopt.workflows.morph_robustness import ISSUE_PLANTS, excess_table, plant_record, sample_plants
from wingopt.workflows.sweep.records import read_records


class _Timed:
    """A controller whose ``step`` CPU time is recorded (thread time: other processes do not count)."""

    def __init__(self, inner):
        self.inner, self.name, self.period, self.cpu = inner, inner.name, inner.period, []

    def reset(self, model, target):
        self.inner.reset(model, target)
        self.cpu = []

    def step(self, y):
        t0 = time.thread_time()
        u = self.inner.step(y)
        self.cpu.append(time.thread_time() - t0)
        return u


def timing(model, t_end: float) -> None:
    print(f"QP step CPU time, {model.problem.nodes[0]}x{model.problem.nodes[1]}, period 10 ms, {t_end:g} s")
    for shape in SHAPES:
        zd = model.target(shape)
        for of in (False, True):
            ctrl = _Timed(make_qp_controller(model, zd, vmin=-500, vmax=1500, period=0.01, offset_free=of))
            simulate_closed_loop(model, ctrl, zd, t_end=t_end, vmin=-500, vmax=1500)
            t = np.asarray(ctrl.cpu[1:])  # the first step pays one-off allocations
            print(
                f"  {shape:8s} offset_free={str(of):5s} p50 {1e3 * np.median(t):.3f} ms  "
                f"p99 {1e3 * np.percentile(t, 99):.3f} ms  p99/period {np.percentile(t, 99) / 0.01:.3f}",
                flush=True,
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", default="13x61")
    ap.add_argument("--plants", type=int, default=20, help="random plants besides the issue's three")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--t-end", type=float, default=2.0)
    ap.add_argument("--timing", action="store_true", help="only the step timing")
    ap.add_argument("--out", help="write the records and the table as JSON")
    ap.add_argument("--figure", help="draw the excess distribution (PNG) of the records")
    ap.add_argument("--records", help="tabulate/draw these records (a --out JSON or a sweep's records.jsonl)")
    args = ap.parse_args()
    if args.records:
        report(_read(args.records), args.figure)
        return
    problem = load_problem("plate").with_mesh(parse_mesh(args.mesh))
    model = PlateModel.from_problem(problem)
    if args.timing:
        timing(model, args.t_end)
        return
    cases = list(ISSUE_PLANTS) + (sample_plants(args.plants, args.seed) if args.plants else [])
    records = []
    for case in cases:
        rec = plant_record(model, case, t_end=args.t_end)
        records.append(rec)
        cells = []
        for shape, by in rec["results"].items():
            r = by["qp"]
            cells.append(
                f"{shape} {r['error']:.4f} (best {r['best']:.4f}, today {by['qp-today']['error']:.4f}, "
                f"lqr {by['lqr-sat']['error']:.4f})"
            )
        print(f"{case.name:18s} {json.dumps(case.scales)} h={case.hysteresis:g}: " + "; ".join(cells), flush=True)
    report(records, args.figure, args.out)


def _read(path: str) -> list[dict]:
    if path.endswith(".jsonl"):
        return [r for r in read_records(path) if r.get("status", "ok") == "ok" and "results" in r]
    with open(path) as fh:
        return json.load(fh)["records"]


def report(records: list[dict], figure: str | None = None, out: str | None = None) -> None:
    table = excess_table(records) + excess_table(records, metric="settled_relative_excess")
    print("\nrelative excess over the plant's best: final error, then the mean shape of the last 0.25 s")
    for row in table:
        print(
            f"  {row['metric'][:7]:7s} {row['shape']:8s} {row['controller']:9s} n={row['plants']:3d} "
            f"median {row['median']:+.4f} "
            f"p90 {row['p90']:+.4f} max {row['max']:+.4f} within 2 % {row['within_0.02']:.2f} "
            f"limits kept {row['within_limits']:.2f}"
        )
    if out:
        with open(out, "w") as fh:
            json.dump({"records": records, "table": table}, fh, indent=1)
    if figure:
        plot_robustness(records, Path(figure))


if __name__ == "__main__":
    main()
