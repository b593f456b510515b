"""Save, then compare, the answers of a fixed set of runs: a restructuring must not move them.

    python benchmarks/same_answers.py save BEFORE.json [--quick]
    python benchmarks/same_answers.py compare BEFORE.json AFTER.json [--rtol 1e-9]

The set (issue 31): the shipped stand-in on every route (sensors, calibration + sensors, DIC,
DIC + calibration, stream), the protocol's L1-L3 through the linear MHE, the tuned JEKF and the FvK
transient route (FvK truth on 49x25), and the calibration itself. Each run keeps its lift, band,
mean load field on a 15x9 grid, status and every number of its ``info`` (flattened). ``compare``
prints each difference beyond ``rtol`` (relative to the larger magnitude), and each run's lift
difference in its own bands. Run both sides with the same thread count
(``OPENBLAS_NUM_THREADS=1``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "examples" / "data"
GRID = (15, 9)


def _flat(prefix: str, value, out: dict) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            _flat(f"{prefix}.{k}", v, out)
    elif isinstance(value, (list, tuple)) and value and all(isinstance(v, (int, float)) for v in value):
        out[prefix] = [float(v) for v in value]
    elif isinstance(value, (bool, str)) or value is None:
        out[prefix] = value
    elif isinstance(value, (int, float, np.floating, np.integer)):
        out[prefix] = float(value)


def _record(run) -> dict:
    res = run.result
    lift, band = res.reported_lift
    xs = np.linspace(0, run.problem.width, GRID[0])
    ys = np.linspace(0, run.problem.height, GRID[1])
    X, Y = np.meshgrid(xs, ys)
    out = {"lift": float(lift), "band": None if band is None else float(band), "status": str(run.status)}
    out["field"] = [float(v) for v in np.asarray(run.load_field()(X, Y)).ravel()]
    _flat("info", {k: v for k, v in res.info.items() if k != "iterations_per_window"}, out)
    return out


def runs(quick: bool) -> dict:
    import wingopt as wo
    from wingopt.workflows.stream import follow

    membrane = wo.load_problem("membrane")
    out: dict[str, dict] = {}

    def timed(name, fn):
        t0 = time.process_time()
        out[name] = fn()
        out[name]["cpu_s"] = time.process_time() - t0
        print(
            f"{name}: lift {out[name].get('lift')} ± {out[name].get('band')} ({out[name]['cpu_s']:.1f} s)",
            file=sys.stderr,
        )

    record = DATA / "tunnel_300Hz.csv"
    cal = wo.calibrate_membrane(membrane, DATA / "tunnel_calibration_300Hz.csv")
    params = {k: float(v) for k, v in cal.calibration.parameters.items()}
    out["calibration"] = {"parameters": params}
    calibrated = wo.calibrated_problem(cal)
    timed("standin/sensors", lambda: _record(wo.identify(membrane, data=record)))
    timed("standin/calibration+sensors", lambda: _record(wo.identify(calibrated, data=record)))
    timed("standin/dic", lambda: _record(wo.identify(membrane, dic=DATA / "tunnel_dic_300Hz.npz")))
    timed("standin/dic+calibration", lambda: _record(wo.identify(calibrated, dic=DATA / "tunnel_dic_300Hz.npz")))

    def stream():
        with tempfile.TemporaryDirectory() as tmp:
            s = follow(membrane, Path(tmp) / "out", source=str(record), idle_timeout=0.2)
        return {"lift": float(s["lift_N"]), "band": s.get("lift_std_N"), "status": s.get("status")}

    timed("standin/stream", stream)
    loads = ("L1",) if quick else ("L1", "L2", "L3")
    for load in loads:
        for method in ("mhe", "jekf-tuned"):
            timed(f"{load}/{method}", lambda lo=load, me=method: _record(wo.identify(membrane, load=lo, method=me)))
        timed(f"{load}/fvk-transient", lambda lo=load: _record(wo.identify(membrane, load=lo, truth="fvk")))
    return out


def _rel(a: float, b: float) -> float:
    scale = max(abs(a), abs(b))
    return 0.0 if scale == 0 else abs(a - b) / scale


def compare(before: dict, after: dict, rtol: float) -> int:
    differences = 0
    for name in before:
        if name not in after:
            print(f"{name}: missing after")
            differences += 1
            continue
        b, a = before[name], after[name]
        if "lift" in b and "lift" in a and b.get("band"):
            print(f"{name}: lift {b['lift']:.6g} -> {a['lift']:.6g} ({(a['lift'] - b['lift']) / b['band']:+.3f} bands)")
        for key in sorted(set(b) | set(a)):
            if key == "cpu_s":
                continue
            vb, va = b.get(key), a.get(key)
            if isinstance(vb, list) and isinstance(va, list) and len(vb) == len(va):
                worst = max((_rel(x, y) for x, y in zip(vb, va)), default=0.0)
                if worst > rtol:
                    print(f"  {key}: max relative difference {worst:.3g}")
                    differences += 1
            elif isinstance(vb, float) and isinstance(va, float):
                if not (math.isnan(vb) and math.isnan(va)) and _rel(vb, va) > rtol:
                    print(f"  {key}: {vb:.10g} -> {va:.10g}")
                    differences += 1
            elif vb != va:
                print(f"  {key}: {vb!r} -> {va!r}")
                differences += 1
    print(f"{differences} differences beyond {rtol:g}")
    return differences


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    s = sub.add_parser("save")
    s.add_argument("path")
    s.add_argument("--quick", action="store_true", help="L1 only")
    c = sub.add_parser("compare")
    c.add_argument("before")
    c.add_argument("after")
    c.add_argument("--rtol", type=float, default=1e-9)
    args = ap.parse_args(argv)
    if args.command == "save":
        Path(args.path).write_text(json.dumps(runs(args.quick), indent=1))
        return 0
    return (
        1
        if compare(json.loads(Path(args.before).read_text()), json.loads(Path(args.after).read_text()), args.rtol)
        else 0
    )


if __name__ == "__main__":
    sys.exit(main())
