"""Model-mismatch study (issue 11): estimators on records from membranes unlike the problem file.

Grid: loads {L1, L2, L3, LE, L1+gust} x truth {linear, berger} x prestrain factor {0.8, 1, 1.2}
(applied to x, and its reciprocal-ish 2 - f to y, so the membrane is stretched unequally) x damping
{0.5, 2} x noise {1 %, 5 %} x seeds; estimators: the linear MHE (seed protocol, with the adequacy
check), the realistic estimator (Berger model, prestrain and damping free) and the tuned JEKF.
Metrics per run: final lift error / ∫|P|, final load-field error, whether the 1-sigma lift band
covers the truth, the adequacy flag, chi-square per datum, parameter errors, wall and CPU time; for
the gust the lift-history RMS (t >= 0.1 s) / steady lift, peak error and peak delay.

The study is a *map over independent tasks*: :func:`tasks` lists plain dicts, :func:`run_task`
runs one (no shared state but a per-process cache of the noise-free truth), so any scheduler can
run it (the Dask sweep engine of ``wingopt.workflows.sweep`` when merged; here a plain loop)::

    nice python benchmarks/mismatch_study.py --subset must-show --out runs/mismatch.jsonl
    nice python benchmarks/mismatch_study.py --loads L1,LE --truths berger --prestrain 0.8,1.2 \\
        --damping 2 --noise 0.01 --seeds 0 --estimators realistic,mhe --out runs/m.jsonl

Truth: the full-order Berger membrane on 49x25 with 8 sub-steps per sample, or the same operators
with the stretch left out (linear), both by :func:`wingopt.workflows.protocols.simulate_case`
(before the model-layer refactor the truth was a 120-mode modal Berger model, the retired
``berger_case``). Results append to a JSON-lines file (one task per line; rerunning skips done
tasks). Quickest run (one task)::

    nice python benchmarks/mismatch_study.py --loads L1 --truths linear --prestrain 1 --damping 2 \\
        --noise 0.01 --seeds 0 --estimators mhe --out /tmp/mismatch_quick.jsonl
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import itertools
import json
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from wingopt.estimation.options import IdentifyOptions  # noqa: E402
from wingopt.estimation.registry import resolve  # noqa: E402
from wingopt.estimation.runners import run_record  # noqa: E402
from wingopt.membrane import Gust, MembraneModel, add_noise  # noqa: E402
from wingopt.problem import load_problem  # noqa: E402
from wingopt.workflows.protocols import simulate_case  # noqa: E402
from wingopt.workflows.studies import load_field  # noqa: E402

ESTIMATORS = ("realistic", "mhe", "jekf-tuned")

ISSUE_GUST = Gust(start=0.4, duration=0.2, amplitude=0.3)
"""The gust of the study: 1-cos, +60 % over 0.2 s, starting at 0.4 s (after the bubble's transient)."""

TRUTH_SUBSTEPS = 8
"""Integration sub-steps per sample of the truth (as the retired ``berger_case``)."""


def tasks(loads, truths, prestrain, damping, noise, seeds, estimators) -> list[dict]:
    """The grid as a list of independent task dicts."""
    out = []
    for load, truth, pf, d, n, s, est in itertools.product(loads, truths, prestrain, damping, noise, seeds, estimators):
        out.append(
            {
                "load": load,
                "truth": truth,
                "prestrain_factor": pf,
                "damping": d,
                "noise": n,
                "seed": s,
                "estimator": est,
            }
        )
    return out


def must_show() -> list[dict]:
    """The issue's Must-show cases (nonlinear truth unless stated)."""
    base = {"truth": "berger", "prestrain_factor": 1.0, "damping": 1.0, "noise": 0.01, "seed": 0}
    out = [{**base, "load": ld, "estimator": "realistic"} for ld in ("L1", "L2", "LE")]
    out += [{**base, "truth": "linear", "load": ld, "estimator": "realistic"} for ld in ("L1", "L2", "LE")]
    out += [{**base, "load": "L1", "prestrain_factor": f, "damping": 2.0, "estimator": "realistic"} for f in (0.8, 1.2)]
    out += [{**base, "load": "L1+gust", "estimator": "realistic"}]
    out += [{**base, "load": "LE", "estimator": "mhe"}, {**base, "load": "L1", "estimator": "mhe"}]
    return out


def coverage(seeds) -> list[dict]:
    base = {"truth": "berger", "prestrain_factor": 1.0, "damping": 1.0, "noise": 0.01, "estimator": "realistic"}
    return [{**base, "load": "L1", "seed": s} for s in seeds]


@functools.lru_cache(maxsize=8)
def _clean(load: str, truth: str, pf: float, damping: float):
    problem = load_problem("membrane")
    e0 = problem.material.prestrain
    gust = ISSUE_GUST if load.endswith("+gust") else None
    name = load.split("+")[0]
    return simulate_case(
        problem, name, 0.0, None, truth="berger" if truth == "berger" else "linear",
        prestrain=(pf * e0, (2.0 - pf) * e0), damping=damping, gust=gust, substeps=TRUTH_SUBSTEPS, tell_noise=False,
    )  # fmt: skip


@functools.lru_cache(maxsize=1)
def _model():
    return MembraneModel.from_problem(load_problem("membrane"))


def run_task(task: dict) -> dict:
    """Run one task; returns the task with its metrics."""
    from wingopt.estimation.records import identify_record

    clean = _clean(task["load"], task["truth"], task["prestrain_factor"], task["damping"])
    noisy, _ = add_noise(clean.trajectory.outputs, task["noise"], task["seed"])
    meas = dataclasses.replace(clean.measurements, values=noisy, noise_std=None)
    model = _model()
    t0, c0 = time.perf_counter(), time.process_time()
    if task["estimator"] == "realistic":
        res = identify_record(model, meas)
    else:
        # the MHE's adequacy check without the FvK cross-check (the study measures the linear estimate)
        res = run_record(resolve(task["estimator"], "linear"), model, meas, IdentifyOptions(model_form=False))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    lift_true = clean.lift_history
    absl = clean.true_absolute_load
    out = dict(task)
    out.update(
        lift=float(res.lift[-1]),
        lift_true=float(lift_true[-1]),
        lift_std=None if res.lift_std is None else float(res.lift_std[-1]),
        lift_error=float((res.lift[-1] - lift_true[-1]) / absl),
        load_error=float(clean.load_error(load_field(res, model))),
        covered=None if res.lift_std is None else bool(abs(res.lift[-1] - lift_true[-1]) <= res.lift_std[-1]),
        model_adequate=res.info.get("model_adequate"),
        chi2_per_datum=(res.info.get("adequacy") or {}).get("chi2_per_datum"),
        warnings=res.info.get("warnings", []),
        wall_s=wall,
        cpu_s=cpu,
    )
    if "parameters" in res.info:
        est, truth = res.info["parameters"], clean.parameters
        out["parameters"], out["parameters_std"], out["true_parameters"] = est, res.info["parameters_std"], truth
        out["parameter_rel_error"] = {k: (est[k] - truth[k]) / truth[k] for k in truth}
        out["load_model"] = res.info["load_model"]
        out["membrane_selection"] = res.info.get("membrane_selection")
    if task["load"].endswith("+gust"):
        k = np.searchsorted(res.t, 0.1)
        idx = np.searchsorted(clean.trajectory.t, res.t)
        lt = lift_true[idx]
        steady = lift_true[0]
        out["gust_rms_over_steady"] = float(np.sqrt(np.mean((res.lift[k:] - lt[k:]) ** 2)) / steady)
        out["gust_peak_error"] = float((res.lift.max() - lt.max()) / lt.max())
        out["gust_delay_ms"] = float(1000 * (res.t[np.argmax(res.lift)] - res.t[np.argmax(lt)]))
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--subset", choices=("must-show", "coverage", "grid"), default="grid")
    ap.add_argument("--loads", default="L1,L2,L3,LE,L1+gust")
    ap.add_argument("--truths", default="linear,berger")
    ap.add_argument("--prestrain", default="0.8,1,1.2")
    ap.add_argument("--damping", default="0.5,2")
    ap.add_argument("--noise", default="0.01,0.05")
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--estimators", default=",".join(ESTIMATORS))
    ap.add_argument("--out", required=True, help="JSON-lines file (appended; done tasks are skipped)")
    a = ap.parse_args(argv)

    def floats(s):
        return [float(x) for x in s.split(",")]

    seeds = [int(x) for x in a.seeds.split(",")] if "-" not in a.seeds else list(range(*map(int, a.seeds.split("-"))))
    if a.subset == "must-show":
        todo = must_show()
    elif a.subset == "coverage":
        todo = coverage(seeds)
    else:
        todo = tasks(
            a.loads.split(","),
            a.truths.split(","),
            floats(a.prestrain),
            floats(a.damping),
            floats(a.noise),
            seeds,
            a.estimators.split(","),
        )
    path = Path(a.out)
    done = set()
    if path.exists():
        done = {json.dumps({k: r[k] for k in todo[0]}, sort_keys=True) for r in map(json.loads, path.open())}
    for task in todo:
        key = json.dumps(task, sort_keys=True)
        if key in done:
            continue
        rec = run_task(task)
        with path.open("a") as fh:
            fh.write(json.dumps(rec) + "\n")
        print(
            f"{task['estimator']:>10} {task['load']:>8} {task['truth']:>6} e{task['prestrain_factor']:g} "
            f"d{task['damping']:g} n{task['noise']:g} s{task['seed']}: lift err {rec['lift_error']:+.4f} "
            f"field {rec['load_error']:.3f} covered {rec['covered']} adequate {rec['model_adequate']} "
            f"cpu {rec['cpu_s']:.1f} s",
            flush=True,
        )


if __name__ == "__main__":
    main()
