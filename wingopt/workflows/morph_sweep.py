"""``wingopt sweep`` of morphing robustness (``kind = "morph"``): mismatched plants on the Dask engine.

A spec (TOML)::

    kind = "morph"
    problem = "plate"             # the controllers' model (problem file or built-in name)
    mesh = "13x61"                # default: the problem's
    t_end = 2.0                   # s per run
    shapes = ["twist", "camber", "bending"]
    controllers = ["qp", "qp-today", "lqr-sat"]
    issue_plants = true           # issue 34's three plants first (nominal, E x1.1 d33 x0.8, E x0.9 d33 x1.2)
    retries = 2

    [plants]                      # random plants (wingopt.workflows.morph_robustness.sample_plants)
    count = 100
    seed = 0
    moduli = [0.9, 1.1]           # a number or [low, high]; damping is drawn log-uniform
    d33 = [0.8, 1.2]
    damping = [0.5, 2.0]
    hysteresis = 0.15             # major-loop width, fraction
    creep = 0.0
    sensor_bias = [0.0, 0.02]     # of each sensor's 1 kV response, random sign
    sensor_noise = 0.0            # m

    [[cases]]                     # explicit plants besides
    name = "soft and weak"
    scales = { moduli = 0.9, d33 = 0.8, damping = 2.0 }
    hysteresis = 0.2

One task per plant (every shape with every controller, :func:`plant_record`), keyed by the plant's
parameters: ``--resume`` runs only the plants not yet recorded. The table (``table.csv``) has one
row per shape, controller and metric: the median, p90 and max of the excess over the plant's best
(relative), the share within 2 %, the share of runs within the voltage limits.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from wingopt.errors import InputError
from wingopt.plate import PlateModel
from wingopt.plate.shapes import SHAPES
from wingopt.problem import load_problem, parse_mesh
from wingopt.workflows.morph_plant import parse_plant_scale
from wingopt.workflows.morph_robustness import (
    CONTROLLERS,
    ISSUE_PLANTS,
    PlantCase,
    excess_table,
    plant_record,
    sample_plants,
)
from wingopt.workflows.sweep.engine import SharedInput, SweepTask

__all__ = ["MorphSweepSpec", "parse_morph_spec", "morph_tasks", "morph_table", "KIND"]

KIND = "morph"
_TOP = {"kind", "problem", "mesh", "t_end", "shapes", "controllers", "issue_plants", "retries", "title", "plants"}
_TOP |= {"cases", "cluster"}
_CASE = {"name", "scales", "hysteresis", "creep", "sensor_bias", "sensor_noise", "seed"}


@dataclass(frozen=True)
class MorphRun:
    """One plant of a morph sweep (``problem``: the controllers' model problem, for the inputs list)."""

    case: PlantCase
    problem: object

    @property
    def params(self) -> dict:
        return self.case.params()


@dataclass(frozen=True)
class MorphSweepSpec:
    """A validated morph-robustness sweep: the model problem, the plants, shapes and controllers."""

    source: str
    title: str
    problem: object
    t_end: float
    shapes: tuple[str, ...]
    controllers: tuple[str, ...]
    runs: tuple[MorphRun, ...]
    retries: int
    cluster: dict
    kind: str = KIND

    @property
    def case_fields(self) -> tuple[str, ...]:
        return ("plant",)


def _err(source, key, value, expected) -> InputError:
    return InputError(f"{source}: {key} = {value!r}: expected {expected}")


def _names(source, data, key, allowed, default) -> tuple[str, ...]:
    vals = data.get(key, list(default))
    if not isinstance(vals, list) or not vals or any(v not in allowed for v in vals):
        raise _err(source, key, vals, f"a non-empty list of {', '.join(allowed)}")
    return tuple(dict.fromkeys(vals))


def _number(source, where, value, lo=0.0, hi=math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
        raise _err(source, where, value, f"a number in [{lo:g}, {hi:g}]")
    return float(value)


def _case(source: str, i: int, t: dict) -> PlantCase:
    where = f"[[cases]] {i + 1} "
    if not isinstance(t, dict):
        raise _err(source, where.strip(), t, "a table")
    unknown = sorted(set(t) - _CASE)
    if unknown:
        raise _err(source, where + unknown[0], t[unknown[0]], f"one of {', '.join(sorted(_CASE))}")
    try:
        scales = parse_plant_scale(t.get("scales", {}))
    except InputError as exc:
        raise InputError(f"{source}: {where}scales: {exc}") from None
    return PlantCase(
        str(t.get("name", f"case {i + 1}")),
        scales,
        hysteresis=_number(source, where + "hysteresis", t.get("hysteresis", 0.0), 0.0, 0.3),
        creep=_number(source, where + "creep", t.get("creep", 0.0), 0.0, 1.0),
        sensor_bias=_number(source, where + "sensor_bias", t.get("sensor_bias", 0.0), -1.0, 1.0),
        sensor_noise=_number(source, where + "sensor_noise", t.get("sensor_noise", 0.0), 0.0, 1.0),
        seed=int(_number(source, where + "seed", t.get("seed", 0), 0, 2**31)),
    )


def parse_morph_spec(data: dict, source: str = "<memory>", base: Path | None = None) -> MorphSweepSpec:
    """Validate a ``kind = "morph"`` spec (see the module docstring)."""
    unknown = sorted(set(data) - _TOP)
    if unknown:
        raise _err(source, unknown[0], data[unknown[0]], f"one of the morph spec keys {', '.join(sorted(_TOP))}")
    name = data.get("problem", "plate")
    if not isinstance(name, str):
        raise _err(source, "problem", name, "a problem file or built-in name")
    given = Path(name)
    if base is not None and not given.is_absolute() and (base / given).is_file():
        name = str(base / given)
    problem = load_problem(name)
    if problem.kind != "plate":
        raise _err(source, "problem", name, "a plate problem")
    if "mesh" in data:
        try:
            problem = problem.with_mesh(parse_mesh(data["mesh"]))
        except InputError:
            raise _err(source, "mesh", data["mesh"], "NXxNY nodes, e.g. 13x61") from None
    t_end = _number(source, "t_end", data.get("t_end", 2.0), 0.01, 60.0)
    shapes = _names(source, data, "shapes", SHAPES, SHAPES)
    controllers = _names(source, data, "controllers", tuple(CONTROLLERS), CONTROLLERS)
    retries = data.get("retries", 2)
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise _err(source, "retries", retries, "a non-negative integer")
    issue = data.get("issue_plants", False)
    if not isinstance(issue, bool):
        raise _err(source, "issue_plants", issue, "true or false")
    cases = list(ISSUE_PLANTS) if issue else []
    raw_cases = data.get("cases", [])
    if not isinstance(raw_cases, list):
        raise _err(source, "cases", raw_cases, "an array of tables ([[cases]])")
    cases += [_case(source, i, t) for i, t in enumerate(raw_cases)]
    plants = data.get("plants")
    if plants is not None:
        if not isinstance(plants, dict):
            raise _err(source, "plants", plants, "a table (count, seed, ranges)")
        ranges = {k: v for k, v in plants.items() if k not in ("count", "seed")}
        try:
            cases += sample_plants(plants.get("count", 20), plants.get("seed", 0), ranges)
        except InputError as exc:
            raise InputError(f"{source}: {exc}") from None
    if not cases:
        raise _err(source, "plants", None, "[plants], [[cases]] or issue_plants = true")
    names = [c.name for c in cases]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        raise _err(source, "cases", dup, "distinct plant names")
    cluster = data.get("cluster", {})
    if not isinstance(cluster, dict):
        raise _err(source, "cluster", cluster, "a table of dask-jobqueue settings")
    runs = tuple(MorphRun(c, problem) for c in cases)
    return MorphSweepSpec(
        source, str(data.get("title", "")), problem, t_end, shapes, controllers, runs, retries, cluster
    )


_MODELS: dict = {}
"""The controllers' model per problem, one per worker process (a plate model caches sparse
factorisations that do not pickle, so it is built where it is used rather than shared)."""


def _task(problem, case: PlantCase, shapes, controllers, t_end) -> dict:
    key = repr(problem)
    if key not in _MODELS or _MODELS[key].problem != problem:
        _MODELS.clear()
        _MODELS[key] = PlateModel.from_problem(problem)
    return plant_record(_MODELS[key], case, shapes, controllers, t_end)


def morph_tasks(spec: MorphSweepSpec) -> tuple[list[SweepTask], list[SharedInput]]:
    """One task per plant (the problem shared; each worker builds the model once)."""
    nx, ny = spec.problem.nodes
    model_key = f"plate-problem/{spec.problem.name}/{nx}x{ny}"
    shared = [SharedInput(model_key, _identity, (spec.problem,))]
    # Seconds, measured: a 2 s run is about 1 s on 7x31 (217 nodes) and grows as nodes^1.5 (13x61: 9 s).
    cost = (nx * ny / 217.0) ** 1.5 * len(spec.shapes) * len(spec.controllers) * spec.t_end / 2.0
    tasks = []
    for run in spec.runs:
        params = {**run.params, "mesh": f"{nx}x{ny}", "t_end": spec.t_end}
        params.update(shapes=list(spec.shapes), controllers=list(spec.controllers))
        key = json_key(params)
        args = (run.case, spec.shapes, spec.controllers, spec.t_end)
        tasks.append(SweepTask(key, _task, args, (model_key,), cost))
    return tasks, shared


def _identity(value):
    return value


def json_key(params: dict) -> str:
    """The key of a task: canonical JSON of its parameters (a plant's, the mesh, duration, shapes)."""
    return json.dumps(params, sort_keys=True, separators=(",", ":"))


def morph_table(records: list[dict]) -> list[dict]:
    """The sweep's table: :func:`excess_table` of the final and the settled shape errors."""
    ok = [r for r in records if r.get("status", "ok") == "ok" and "results" in r]
    return excess_table(ok) + excess_table(ok, metric="settled_relative_excess")
