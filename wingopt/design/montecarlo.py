"""Monte Carlo through the real estimator: one identification per (layout, load, noise seed) task.

A task is a plain, picklable :class:`IdentifyTask` and :func:`run_task` a plain function of it, so
a study is ``map(run_task, tasks)`` — serially here, or handed unchanged to a parallel study
engine (a Dask sweep maps exactly such functions). The truth of each load is simulated once per
process (fine mesh, from the protocol's bubble) and reused for every layout: a layout only
changes which quadratic forms of the same deflection history are read.

Loads are named, so a task stays small: ``L1``, ``L2``, ``L3``, ``consistency``, ``leading-edge``
and ``smooth:SEED:K`` (draw ``K`` of :func:`~wingopt.design.priors.smooth_loads` with ``SEED``;
``smooth:SEED:K:ELL`` with the length scale ``ELL`` as a fraction of the chord, default 0.3) and
``edge:SEED:K`` (draw ``K`` of the edge-heavy :func:`~wingopt.design.priors.edge_loads`).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from wingopt.design.priors import edge_loads, leading_edge_suction, smooth_loads
from wingopt.errors import InputError
from wingopt.estimation.declaration import declaration_of
from wingopt.estimation.mhe import MHESettings
from wingopt.estimation.options import IdentifyOptions
from wingopt.estimation.registry import resolve
from wingopt.estimation.runners import run_record
from wingopt.fe import integrate
from wingopt.measurements.series import Measurements
from wingopt.membrane import (
    LOAD_CASES,
    MembraneModel,
    PressureLoad,
    RecordProtocol,
    StretchSensors,
    forward_model,
    load_case,
    simulate_truth,
)
from wingopt.problem.membrane import MembraneProblem, StretchSensorSpec

__all__ = ["IdentifyTask", "run_task", "run_tasks", "named_load", "layout_specs"]

log = logging.getLogger(__name__)

_CACHE: dict = {}


def named_load(name: str, width: float, height: float) -> PressureLoad:
    """The pressure of a load name (see the module docstring)."""
    if name in LOAD_CASES:
        return load_case(name, width, height)
    if name == "leading-edge":
        return leading_edge_suction(width, height)
    if name.startswith("smooth:"):
        try:
            _, seed, k, *ell = name.split(":")
            seed, k = int(seed), int(k)
            frac = float(ell[0]) if ell else 0.3
            if k < 0 or len(ell) > 1 or not frac > 0:
                raise ValueError
        except ValueError:
            raise InputError(f"load = {name!r}: expected smooth:SEED:K or smooth:SEED:K:ELL (ELL > 0)") from None
        return smooth_loads(width, height, k + 1, seed, frac * width)[k]
    if name.startswith("edge:"):
        try:
            _, seed, k = name.split(":")
            seed, k = int(seed), int(k)
            if k < 0:
                raise ValueError
        except ValueError:
            raise InputError(f"load = {name!r}: expected edge:SEED:K") from None
        return edge_loads(width, height, k + 1, seed)[k]
    raise InputError(
        f"load = {name!r}: expected L1, L2, L3, consistency, leading-edge, smooth:SEED:K[:ELL] or edge:SEED:K"
    )


def layout_specs(rects, prefix: str = "S") -> tuple[StretchSensorSpec, ...]:
    """Sensor specs ``S1..SK`` of rectangles ``(K, 4)``."""
    return tuple(StretchSensorSpec(f"{prefix}{i + 1}", tuple(float(v) for v in r)) for i, r in enumerate(rects))


@dataclass(frozen=True)
class IdentifyTask:
    """One identification: a layout (rectangles), a named load, noise fraction and seed.

    ``truth_nodes`` is the simulated truth's mesh, ``nodes`` the estimator's (``None``: the
    problem's), ``t_end`` the record length. ``tag`` is carried to the result (e.g. a layout id).
    """

    problem: MembraneProblem
    rects: tuple[tuple[float, float, float, float], ...]
    load: str
    noise_fraction: float = 0.01
    seed: int = 0
    truth_nodes: tuple[int, int] = (49, 25)
    nodes: tuple[int, int] | None = None
    t_end: float = 0.3
    tag: object = None


def _truth(problem: MembraneProblem, load: str, nodes: tuple[int, int], t_end: float):
    key = (problem, load, tuple(nodes), t_end)  # by value: tasks arrive unpickled (new objects)
    if key not in _CACHE:
        P = named_load(load, problem.width, problem.height)
        fwd = forward_model(problem, "linear", nodes=tuple(nodes))
        model, traj = fwd.model, simulate_truth(fwd, P, RecordProtocol(t_end=t_end)).trajectory
        lift = integrate(model.space, P, order=8)
        absl = integrate(model.space, lambda x, y: np.abs(P(x, y)), order=8)
        norm = integrate(model.space, lambda x, y: P(x, y) ** 2, order=8)
        if len(_CACHE) > 64:
            _CACHE.clear()
        _CACHE[key] = (P, model, traj, lift, absl, norm)
    return _CACHE[key]


def _estimator_model(problem: MembraneProblem, specs, nodes) -> MembraneModel:
    key = ("model", problem, tuple(s.rect for s in specs), nodes)
    if key not in _CACHE:
        prob = problem.with_sensors(specs)
        if nodes is not None:
            prob = prob.with_mesh(nodes)
        if len(_CACHE) > 64:
            _CACHE.clear()
        _CACHE[key] = MembraneModel.from_problem(prob)
    return _CACHE[key]


def run_task(task: IdentifyTask, settings: MHESettings | None = None) -> dict:
    """Run the MHE (:func:`wingopt.estimation.runners.run_record`) on one simulated record; returns
    the task's key fields and the final errors.

    Errors as in the protocol: relative L2 of the load over the membrane (truth mesh), lift error
    ``|lift - true| / ∫|P|``. The sign prior is the protocol's (+, - for the consistency load).
    """
    t0 = time.perf_counter()
    prob = task.problem
    specs = layout_specs(task.rects)
    P, tmodel, traj, lift, absl, norm = _truth(prob, task.load, task.truth_nodes, task.t_end)
    sensors = StretchSensors.assemble(tmodel.space, specs)
    clean = sensors.outputs(traj.z)
    rng = np.random.default_rng(task.seed)
    sigma = task.noise_fraction * np.max(np.abs(clean), axis=0)
    noisy = clean + rng.standard_normal(clean.shape) * sigma
    meas = Measurements(traj.t, noisy, tuple(s.name for s in specs), None, "monte-carlo record", simulated=True)
    model = _estimator_model(prob, specs, task.nodes)
    sign = -1.0 if task.load == "consistency" else 1.0
    # The linear MHE as the registry runs it; no FvK cross-check (model_form): only the estimate counts.
    options = IdentifyOptions(initial_load=sign * abs(declaration_of(prob).initial_load), model_form=False)
    res = run_record(resolve("mhe", "linear"), model, meas, options, settings=settings)
    space = model.space if res.load_space is None else res.load_space  # the result's own load basis
    err2 = integrate(
        tmodel.space, lambda x, y: (P(x, y) - space.evaluate(res.final_load, x, y).reshape(x.shape)) ** 2, order=8
    )
    return {
        "tag": task.tag,
        "load": task.load,
        "seed": task.seed,
        "noise_fraction": task.noise_fraction,
        "load_error": float(np.sqrt(err2 / norm)),
        "lift_error": float(abs(res.reported_lift[0] - lift) / absl),
        "lift": res.reported_lift[0],
        "true_lift": float(lift),
        "regularization": float(res.regularization),
        "wall_s": time.perf_counter() - t0,
    }


def run_tasks(
    tasks: Iterable[IdentifyTask],
    mapper: Callable | None = None,
    progress: Callable[[int, dict], None] | None = None,
) -> list[dict]:
    """``mapper(run_task, tasks)`` (default: the serial ``map``); ``progress(i, record)`` per result."""
    tasks = list(tasks)
    mapper = map if mapper is None else mapper
    out = []
    for i, rec in enumerate(mapper(run_task, tasks)):
        out.append(rec)
        if progress is not None:
            progress(i, rec)
    return out


def with_rects(task: IdentifyTask, rects) -> IdentifyTask:
    return dataclasses.replace(task, rects=tuple(tuple(float(v) for v in r) for r in rects))
