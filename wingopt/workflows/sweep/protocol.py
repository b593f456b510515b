"""Task functions and task lists of the simulated-protocol studies (comparison, sign, consistency).

Each (case, noise seed, method) run is one :class:`~wingopt.workflows.sweep.engine.SweepTask`.
Its shared inputs are the noise-free truth of its load (simulated once on the fine mesh) and
the estimator's model (built once per problem); the task adds the seeded noise, runs the method
and returns the :class:`~wingopt.workflows.studies.CaseRecord` as a dict, with the run's
parameters under ``"params"``. The task key is the canonical JSON of those parameters, so
the records of an earlier run (also of the pre-engine ``compare``) are matched by ``--resume``.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Iterable, Sequence

import numpy as np

from wingopt import resources
from wingopt.errors import SolverError
from wingopt.estimation.mhe import MHESettings
from wingopt.estimation.options import IdentifyOptions
from wingopt.estimation.registry import EstimatorSpec, resolve
from wingopt.estimation.runners import run_record
from wingopt.membrane import MembraneModel, TruthRecord
from wingopt.problem.membrane import MembraneProblem
from wingopt.workflows.protocols import simulate_case
from wingopt.workflows.studies import (
    ORACLE_OFFSETS,
    evaluate,
    noisy_case,
    oracle_lambda,
    protocol_sign,
    sensor_grid,
)
from wingopt.workflows.sweep.engine import Engine, EngineSettings, SharedInput, SweepTask

__all__ = [
    "task_key",
    "digest",
    "ORACLE_OFFSETS",
    "simulate_clean",
    "build_model",
    "protocol_record",
    "task_cost",
    "has_oracle",
    "estimator",
    "protocol_tasks",
    "consistency_tasks",
    "CONSISTENCY_LAYOUTS",
    "run_tasks",
    "consistency_rows",
    "lift_history",
]

CONSISTENCY_LAYOUTS = (None, (4, 3), (8, 4))
"""The consistency study's sensor layouts: the problem's own, then 4x3 and 8x4 grids."""


def task_key(params: dict) -> str:
    """The key of a run: canonical JSON of its parameters."""
    return json.dumps(params, sort_keys=True, separators=(",", ":"))


def digest(*parts) -> str:
    return hashlib.sha1(repr(parts).encode()).hexdigest()[:16]


def simulate_clean(problem: MembraneProblem, load: str, truth_nodes, t_end: float) -> TruthRecord:
    """The noise-free protocol run of ``load`` (truth on ``truth_nodes``): a shared input."""
    return simulate_case(problem, load, 0.0, None, truth_nodes, t_end)


def build_model(problem: MembraneProblem) -> MembraneModel:
    """The estimator's model of ``problem``: a shared input."""
    return MembraneModel.from_problem(problem)


def protocol_record(
    clean: TruthRecord,
    model: MembraneModel,
    params: dict,
    method: str,
    noise: float,
    seed: int,
    settings: MHESettings | None,
    initial_load: float,
    oracle_offsets: Sequence[float] | None = None,
    jekf_modes: int | None = None,
    history: bool = False,
) -> dict:
    """One run: seeded noise on the clean truth, ``method`` on it, final metrics (and the oracle lambda).

    ``jekf_modes``: a JEKF keeps only its lowest ``jekf_modes`` modes (``None``: all, exact).
    ``history``: the record keeps the lift history (:func:`lift_history`, ~10 kB) for the overlay plots.
    """
    case = noisy_case(clean, noise, seed)
    t0 = time.perf_counter()
    spec = estimator(method)
    options = IdentifyOptions(initial_load=initial_load, modes=jekf_modes if spec.method.startswith("jekf") else None)
    res = run_record(
        spec, model, case.measurements, options, truth=case, settings=settings if has_oracle(spec) else None
    )
    rec = evaluate(case, res, model, method)
    rec.wall_s = time.perf_counter() - t0
    if oracle_offsets and has_oracle(spec):
        grid = [rec.regularization * 10.0**e for e in oracle_offsets]
        lam, err, _ = oracle_lambda(case, model, settings or MHESettings(), grid, initial_load=initial_load)
        rec.oracle_regularization, rec.oracle_load_error = lam, min(err, rec.load_error)
    out = {**rec.as_dict(), "params": params}
    if history:
        out["history"] = lift_history(res)
    return out


HISTORY_POINTS = 201
"""Samples of the lift history kept in a study record (for the MHE–JEKF overlay plot)."""


def lift_history(result, points: int = HISTORY_POINTS) -> dict:
    """The lift history of ``result`` on at most ``points`` evenly spaced samples (JSON lists)."""
    t = np.asarray(result.t, dtype=float)
    idx = np.unique(np.linspace(0, t.size - 1, min(points, t.size)).astype(int))
    lift = np.asarray(result.lift, dtype=float)[idx]
    std = None if result.lift_std is None else np.asarray(result.lift_std, dtype=float)[idx]
    return {
        "t": [round(float(v), 9) for v in t[idx]],
        "lift_N": [float(f"{v:.6g}") for v in lift],
        "lift_std_N": None if std is None else [float(f"{v:.4g}") if np.isfinite(v) else None for v in std],
    }


def estimator(method: str) -> EstimatorSpec:
    """The registry's record estimator of a study's ``method`` on the protocol's simulated (linear) truth:
    a study runs any estimator as ``wingopt identify --load`` does (``auto`` included)."""
    return resolve(method, simulated="linear")


def has_oracle(spec: EstimatorSpec) -> bool:
    """Whether a study finds the oracle lambda of the registry's estimator ``spec``: the one that runs
    on :class:`MHESettings` (the oracle reruns it on a grid of its lambda, and the study's MHE
    settings are its)."""
    return spec.settings is MHESettings


def task_cost(
    method: str, model_nodes, t_end: float, oracle: bool, jekf_modes: int | None = None, dt: float = 1e-3
) -> float:
    """Run-time estimate (s) of one run: the size estimate of :func:`wingopt.resources.estimate_identify`,
    times the runs of the oracle-lambda grid (the engine submits the cheapest first: early results)."""
    spec = estimator(method)
    seconds = resources.estimate_identify(
        tuple(model_nodes), int(round(t_end / dt)) + 1, method=spec.method, jekf_modes=jekf_modes
    ).seconds
    return seconds * (1 + len(ORACLE_OFFSETS) if oracle and has_oracle(spec) else 1)


def protocol_tasks(
    problem: MembraneProblem,
    runs: Iterable[tuple[str, float, int, str]],
    settings: MHESettings | None = None,
    truth_nodes: tuple[int, int] | None = (49, 25),
    oracle: bool = False,
    oracle_offsets: Sequence[float] = ORACLE_OFFSETS,
    t_end: float = 1.0,
    jekf_modes: int | None = None,
    histories: bool = False,
) -> tuple[list[SweepTask], list[SharedInput]]:
    """Tasks of ``runs`` = (load, noise fraction, seed, method) on ``problem`` (the comparison preset).

    Keys are ``task_key({"load", "noise", "seed", "method"})``: the fields of every comparison record;
    a JEKF at a reduced order (``jekf_modes``: its lowest modes only) adds ``"jekf_modes"``, so that
    its records and the exact filter's are never taken for each other (``--resume``). ``histories``:
    the records keep their lift histories (the comparison table's, for the overlay plots).
    """
    model_key = f"model/{digest(problem)}"
    shared = {model_key: SharedInput(model_key, build_model, (problem,))}
    tasks: dict[str, SweepTask] = {}
    for load, noise, seed, method in runs:
        params = {"load": load, "noise": float(noise), "seed": int(seed), "method": method}
        modes = jekf_modes if method.startswith("jekf") and jekf_modes is not None else None
        if modes is not None:
            params["jekf_modes"] = int(modes)
        truth_key = f"truth/{digest(problem, load, truth_nodes, t_end)}/{load}"
        shared.setdefault(truth_key, SharedInput(truth_key, simulate_clean, (problem, load, truth_nodes, t_end)))
        sign = protocol_sign(load) * abs(problem.identification.initial_load)
        offsets = tuple(oracle_offsets) if oracle and has_oracle(estimator(method)) else None
        args = (params, method, float(noise), int(seed), settings, sign, offsets, modes, histories)
        key = task_key(params)
        cost = task_cost(method, problem.nodes, t_end, bool(offsets), modes)
        tasks.setdefault(key, SweepTask(key, protocol_record, args, (truth_key, model_key), cost))
    return list(tasks.values()), list(shared.values())


def consistency_tasks(
    problem: MembraneProblem,
    layouts: Sequence[tuple[int, int] | None] = CONSISTENCY_LAYOUTS,
    noise: float = 0.01,
    seeds: Iterable[int] = range(3),
    settings: MHESettings | None = None,
    truth_nodes: tuple[int, int] | None = (49, 25),
    t_end: float = 1.0,
) -> tuple[list[SweepTask], list[SharedInput]]:
    """The consistency study: the rectangle load, the MHE, one task per (sensor layout, seed)."""
    tasks, shared = [], {}
    sign = protocol_sign("consistency") * abs(problem.identification.initial_load)
    seeds = list(seeds)
    for layout in layouts:
        prob = problem if layout is None else problem.with_sensors(sensor_grid(problem, *layout))
        name = "problem" if layout is None else f"{layout[0]}x{layout[1]}"
        model_key, truth_key = f"model/{digest(prob)}", f"truth/{digest(prob, truth_nodes, t_end)}/consistency"
        shared[model_key] = SharedInput(model_key, build_model, (prob,))
        shared[truth_key] = SharedInput(truth_key, simulate_clean, (prob, "consistency", truth_nodes, t_end))
        for seed in seeds:
            params = {"study": "consistency", "layout": name, "sensors": len(prob.sensors)}
            params.update(noise=noise, seed=seed)
            args = (params, "mhe", float(noise), int(seed), settings, sign, None)
            cost = task_cost("mhe", prob.nodes, t_end, False)
            tasks.append(SweepTask(task_key(params), protocol_record, args, (truth_key, model_key), cost))
    return tasks, list(shared.values())


def run_tasks(tasks, shared, jobs: int, engine) -> list[dict]:
    """Run study tasks on ``engine`` (an entered :class:`~wingopt.workflows.sweep.engine.Engine`), or
    in this process (``jobs <= 1``), or on a local cluster of ``jobs`` workers; failures raise."""

    def collect(eng):
        out = []
        for rec in eng.run(tasks, shared):
            if rec["status"] != "ok":
                raise SolverError(
                    f"study task {rec['key']}", str(rec["error"]), "see the task's record in records.jsonl"
                )
            out.append(rec)
        return out

    if engine is not None:
        return collect(engine)
    mode = "serial" if jobs <= 1 or len(tasks) <= 1 else "local"
    with Engine(EngineSettings(mode=mode, workers=jobs, progress=False, dashboard=False)) as eng:
        return collect(eng)


def consistency_rows(records: Sequence[dict]) -> list[dict]:
    """Per sensor layout (in order of appearance): mean and spread of the load error over seeds."""
    groups: dict[str, list[dict]] = {}
    for r in records:
        groups.setdefault(r["params"]["layout"], []).append(r)
    out = []
    for layout, rs in groups.items():
        errs = [r["load_error"] for r in rs]
        out.append(
            {
                "sensors": int(rs[0]["params"]["sensors"]),
                "layout": layout,
                "load_error_mean": float(np.mean(errs)),
                "load_error_min": float(np.min(errs)),
                "load_error_max": float(np.max(errs)),
                "lift_error_mean": float(np.mean([r["lift_error"] for r in rs])),
                "seconds": float(sum(r.get("duration_s", r["wall_s"]) for r in rs)),
            }
        )
    return out
