"""The default `wingopt identify --data` path on FvK records off the protocol (issue 11's safety rule).

Each case is a Föppl–von Kármán record (49x25 truth, the problem's four sensors) that departs from
the seed protocol in one way the estimator is not told about: noise, load level and sign, a load the
smooth load shapes cannot hold, unequal prestrain with heavy damping, a late gust, another sample
rate, a longer record, no initial bubble, a record that starts with the wing already loaded. The record goes through
:func:`wingopt.workflows.identify.identify` exactly as a measured CSV would (``data=`` an array,
noise estimated from the data, every default). One JSON line per case: lift error relative to the
lift, the reported 1-sigma band, the error in bands, whether the band covers, the adequacy flag and
the warnings. The rule checked: no case may report an error of more than 2 bands *and* call itself
adequate without a warning (a confident wrong answer). ::

    nice python benchmarks/realistic_robustness.py            # all cases, about 5 min CPU
    nice python benchmarks/realistic_robustness.py --cases suction,bump
    nice python benchmarks/realistic_robustness.py --cases steady-start --seed 1 --max-iter 200
    nice python benchmarks/realistic_robustness.py --cases light     # quickest

Records: :func:`wingopt.workflows.protocols.simulate_case` (``truth="fvk"``, 49x25, 2 sub-steps).
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from wingopt.estimation.records import RecordSettings  # noqa: E402
from wingopt.membrane import Gust, PressureLoad, load_case  # noqa: E402
from wingopt.problem import load_problem  # noqa: E402
from wingopt.workflows.identify import identify  # noqa: E402
from wingopt.workflows.protocols import simulate_case  # noqa: E402


def _scaled(name: str, factor: float, W: float, L: float) -> PressureLoad:
    base = load_case(name, W, L)
    return PressureLoad(f"{factor:g} x {name}", lambda x, y: factor * base(x, y), base.description)


def _bump(W: float, L: float) -> PressureLoad:
    """An off-centre Gaussian bump (200 Pa peak at (0.7 W, 0.3 L), width 0.12 W)."""
    s = 0.12 * W
    return PressureLoad("bump", lambda x, y: 200.0 * np.exp(-((x - 0.7 * W) ** 2 + (y - 0.3 * L) ** 2) / (2 * s * s)))


def cases(problem) -> dict:
    W, L, e0 = problem.width, problem.height, problem.material.prestrain
    return {
        "noise5": dict(load="L1", noise=0.05),
        "light": dict(load=_scaled("L1", 0.25, W, L)),
        "heavy": dict(load=_scaled("L1", 2.0, W, L)),
        "suction": dict(load=_scaled("L1", -1.0, W, L)),
        "bump": dict(load=_bump(W, L)),
        "L3": dict(load="L3"),
        "LE-unequal-d2": dict(load="LE", prestrain=(1.2 * e0, 0.8 * e0), damping=2.0),
        "late-gust": dict(load="L1", gust=Gust(start=0.7, duration=0.2, amplitude=0.3)),
        "500Hz": dict(load="L1", dt=2e-3),
        "2s": dict(load="L1", t_end=2.0),
        "no-bubble": dict(load="L1", start="rest"),
        "steady-start": dict(load="L1", skip_s=0.5),
    }


def run(name: str, spec: dict, problem, seed: int, max_iter: int | None = None) -> dict:
    spec = dict(spec)
    noise = spec.pop("noise", 0.01)
    skip = spec.pop("skip_s", 0.0)  # the record starts this late: the wing already loaded, no transient
    t_end = spec.pop("t_end", 1.0) + skip
    load = spec.pop("load")
    rec = simulate_case(problem, load, noise, seed, t_end=t_end, truth="fvk", tell_noise=False, **spec)
    t, values = rec.measurements.t, rec.measurements.values
    k = int(np.searchsorted(t, skip - 1e-12))
    data = np.column_stack([t[k:] - t[k], values[k:]])
    c0 = time.process_time()
    settings = None if max_iter is None else RecordSettings(max_iter=max_iter)
    out = identify(problem, data=data, settings=settings)
    cpu = time.process_time() - c0
    res = out.result
    lt = float(rec.lift_history[-1])
    lift, std = float(res.lift[-1]), float(res.lift_std[-1]) if res.lift_std is not None else float("nan")
    err = lift - lt
    adequate = res.info.get("model_adequate")
    confident_wrong = abs(err) > 2 * std and adequate is not False and not out.warnings
    return {
        "case": name,
        "seed": seed,
        "true_lift_N": lt,
        "lift_N": lift,
        "band_N": std,
        "error_rel": err / lt if lt else None,
        "error_in_bands": abs(err) / std if std > 0 else None,
        "covered": bool(abs(err) <= std),
        "adequate": adequate,
        "model": res.info.get("model"),
        "load_model": res.info.get("load_model"),
        "warnings": out.warnings,
        "confident_wrong": bool(confident_wrong),
        "cpu_s": cpu,
    }


def main(argv=None) -> None:
    problem = load_problem("membrane")
    all_cases = cases(problem)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(all_cases), help="comma-separated: " + ", ".join(all_cases))
    ap.add_argument("--seed", type=int, default=0, help="noise seed")
    ap.add_argument("--max-iter", type=int, default=None, help="Levenberg-Marquardt cap (default: the estimator's, 40)")
    a = ap.parse_args(argv)
    bad = 0
    for name in a.cases.split(","):
        if name not in all_cases:
            raise SystemExit(f"--cases: {name!r} is not one of {', '.join(all_cases)}")
        row = run(name, all_cases[name], problem, a.seed, a.max_iter)
        bad += row["confident_wrong"]
        print(json.dumps(row), flush=True)
    print(json.dumps({"cases": len(a.cases.split(",")), "confident_wrong": bad}))


if __name__ == "__main__":
    main()
