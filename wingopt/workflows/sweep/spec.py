"""Sweep specs: a TOML file naming the problem and the values to sweep.

Example (docs/studies.md has the full reference)::

    problem = "membrane"          # problem file or built-in name (the estimator's problem)
    truth_mesh = "25x13"          # mesh of the simulated truth (default 49x25)
    t_end = 0.2                   # s, simulated record length (default 1.0)
    oracle = false                # MHE oracle-lambda runs (default false)
    retries = 2                   # re-runs of a task whose worker died or that raised

    [grid]                        # the product of every list
    load = ["L1", "L2"]
    noise = [1, 5]                # percent of each sensor's peak
    seed = [0, 1, 2]
    method = ["mhe", "jekf-tuned"]
    "material.prestrain" = [0.045, 0.05]        # any problem-file field: truth and estimator
    "truth.material.prestrain" = [0.04, 0.06]   # the truth's only (model mismatch)
    "estimator.window" = [100, 200]              # an MHESettings field (MHE runs)

    [[cases]]                     # optional list of cases, each crossed with [grid]
    load = "L3"

    [cluster]                     # dask-jobqueue keywords for --cluster slurm|pbs
    cores = 16
    memory = "32GB"
    walltime = "02:00:00"
    jobs = 4

Every case is validated when the spec is read; errors are one line naming the field.
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wingopt import resources
from wingopt.errors import InputError, ProblemFileError
from wingopt.estimation.mhe import MHESettings
from wingopt.estimation.registry import METHOD_ALIASES, METHODS, resolve
from wingopt.membrane.loads import LOAD_CASES
from wingopt.problem import load_problem, parse_mesh, parse_problem
from wingopt.problem.membrane import MembraneProblem
from wingopt.resources import LIMITS
from wingopt.workflows import morph_sweep

__all__ = ["SweepSpec", "Run", "load_spec", "parse_spec", "AXES"]

AXES = ("load", "noise", "seed", "method", "truth_mesh", "t_end")
"""Named axes; other axis names are dotted problem-file fields, ``truth.<field>`` or ``estimator.<field>``."""

_DEFAULTS = {"noise": 1.0, "seed": 0, "method": "mhe", "truth_mesh": "49x25", "t_end": 1.0}
_TOP = {"problem", "truth_mesh", "t_end", "oracle", "retries", "title", "grid", "cases", "cluster"}
_MHE_FIELDS = {f.name for f in dataclasses.fields(MHESettings)}


@dataclass(frozen=True)
class Run:
    """One resolved run of a sweep: its parameters (the record's ``params``) and what they mean."""

    params: dict
    problem: MembraneProblem
    truth_problem: MembraneProblem
    settings: MHESettings
    truth_nodes: tuple[int, int]
    t_end: float

    @property
    def load(self) -> str:
        return self.params["load"]

    @property
    def noise_fraction(self) -> float:
        """Noise as a fraction, 0.01 = 1 % (the spec's ``noise`` is in percent)."""
        return self.params["noise"] / 100.0


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep spec: the runs in order, and the engine's settings from the file."""

    source: str
    title: str
    runs: tuple[Run, ...]
    oracle: bool
    retries: int
    cluster: dict
    varied: tuple[str, ...]

    @property
    def case_fields(self) -> tuple[str, ...]:
        """The parameters that define a case (all varied ones except the seed)."""
        return tuple(k for k in self.varied if k != "seed")


def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a sweep spec file."""
    from wingopt.resources import check_input_file

    if isinstance(path, bytes) or not isinstance(path, (str, Path)) or not str(path).strip():
        raise InputError(f"spec = {path!r}: expected the path of a sweep spec (TOML)")
    path = Path(path)
    check_input_file(path, "spec")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(f"spec = {str(path)!r}: cannot read it ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise InputError(f"spec = {str(path)!r}: not a UTF-8 text file") from None
    except RecursionError:
        raise InputError(f"spec = {str(path)!r}: nested too deeply to be a sweep spec") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    return parse_spec(data, str(path), base=path.parent)


def _err(source: str, where: str, key: str, value: Any, expected: str) -> InputError:
    return InputError(f"{source}: {where}{key} = {value!r}: expected {expected}")


def _set(doc: dict, dotted: str, value: Any, source: str, where: str) -> None:
    """``doc[a][b][c] = value`` for ``a.b.c`` (integers index arrays of tables, e.g. ``sensors.0.gain``)."""
    parts = dotted.split(".")
    node: Any = doc
    for i, part in enumerate(parts[:-1]):
        if isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        elif isinstance(node, dict):
            node = node.setdefault(part, {})
        else:
            inner = ".".join(parts[: i + 1])
            raise _err(source, where, dotted, value, f"a problem-file field ({inner} is not a table)")
    if isinstance(node, list) and parts[-1].isdigit() and int(parts[-1]) < len(node):
        node[int(parts[-1])] = value
    elif isinstance(node, dict):
        node[parts[-1]] = value
    else:
        raise _err(source, where, dotted, value, "a problem-file field")


class _Problems:
    """The spec's problem with overrides applied, validated by the problem-file reader, cached."""

    def __init__(self, name: str, source: str, base: Path) -> None:
        given = Path(name)
        if not given.is_absolute() and (base / given).is_file():
            name = str(base / given)
        self.base = load_problem(name)
        if self.base.kind != "membrane":
            raise InputError(f"{source}: problem = {name!r}: expected a membrane problem")
        with open(self.base.source, "rb") as fh:
            self.raw = tomllib.load(fh)
        self.source = source
        self._cache: dict[str, MembraneProblem] = {}

    def get(self, overrides: dict[str, Any], where: str) -> MembraneProblem:
        if not overrides:
            return self.base
        key = repr(sorted(overrides.items()))
        if key not in self._cache:
            doc = copy.deepcopy(self.raw)
            for dotted, value in overrides.items():
                _set(doc, dotted, value, self.source, where)
            try:
                prob = parse_problem(doc, f"{self.source} {where}".rstrip(), self.base.name)
            except ProblemFileError as exc:
                raise InputError(str(exc)) from None
            self._cache[key] = dataclasses.replace(prob, source=self.base.source)
        return self._cache[key]


def _check_axis(source: str, where: str, key: str, value: Any) -> Any:
    """Validate one axis value; returns it normalised."""
    if key == "load":
        if value not in LOAD_CASES:
            raise _err(source, where, key, value, f"one of {', '.join(LOAD_CASES)}")
    elif key == "noise":
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < 100:
            raise _err(source, where, key, value, "a noise level in percent, 0 <= noise < 100")
        return float(value)
    elif key == "seed":
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise _err(source, where, key, value, "a non-negative integer")
    elif key == "method":
        if value not in METHODS + tuple(METHOD_ALIASES):
            raise _err(source, where, key, value, f"one of {', '.join(METHODS)}")
        try:  # a record estimator of the registry on the protocol's simulated truth, as identify --load runs it
            resolve(value, simulated="linear")
        except InputError as exc:
            raise _err(source, where, key, value, f"a record estimator of simulated sensor data ({exc})") from None
    elif key == "truth_mesh":
        try:
            parse_mesh(value)
        except InputError:
            raise _err(source, where, key, value, "NXxNY nodes, e.g. 49x25") from None
    elif key == "t_end":
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (value > 0 and math.isfinite(value)):
            raise _err(source, where, key, value, "a positive time in s")
        return float(value)
    elif key.startswith("estimator."):
        if key[len("estimator.") :] not in _MHE_FIELDS:
            raise _err(source, where, key, value, f"an MHESettings field ({', '.join(sorted(_MHE_FIELDS))})")
    elif not key or key.startswith(".") or key.endswith("."):
        raise _err(source, where, key, value, "a named axis or a dotted problem-file field")
    return value


def _values(source: str, where: str, key: str, value: Any) -> list:
    vals = value if isinstance(value, list) else [value]
    if not vals:
        raise _err(source, where, key, value, "at least one value")
    return [_check_axis(source, where, key, v) for v in vals]


def parse_spec(data: dict, source: str = "<memory>", base: Path | None = None) -> SweepSpec:
    """Validate a parsed sweep spec (see the module docstring for the format)."""
    if isinstance(data, dict) and data.get("kind") == morph_sweep.KIND:  # morphing robustness (issue 34)
        return morph_sweep.parse_morph_spec(data, source, base)
    unknown = sorted(set(data) - _TOP)
    if unknown:
        raise _err(source, "", unknown[0], data[unknown[0]], f"one of the spec keys {', '.join(sorted(_TOP))}")
    if not isinstance(data.get("problem"), str):
        raise _err(source, "", "problem", data.get("problem"), "a problem file or built-in name")
    problems = _Problems(data["problem"], source, base or Path("."))
    defaults = dict(_DEFAULTS)
    for key in ("truth_mesh", "t_end"):
        if key in data:
            defaults[key] = _check_axis(source, "", key, data[key])
    oracle, retries = data.get("oracle", False), data.get("retries", 2)
    if not isinstance(oracle, bool):
        raise _err(source, "", "oracle", oracle, "true or false")
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise _err(source, "", "retries", retries, "a non-negative integer")
    grid = data.get("grid", {})
    if not isinstance(grid, dict):
        raise _err(source, "", "grid", grid, "a table of axis = [values]")
    axes = {k: _values(source, "[grid] ", k, v) for k, v in grid.items()}
    cases = data.get("cases", [{}])
    if not isinstance(cases, list) or not all(isinstance(c, dict) for c in cases):
        raise _err(source, "", "cases", cases, "an array of tables ([[cases]])")
    cluster = data.get("cluster", {})
    if not isinstance(cluster, dict):
        raise _err(source, "", "cluster", cluster, "a table of dask-jobqueue settings")
    count = len(cases) * math.prod(len(v) for v in axes.values())
    if count > LIMITS["tasks"]:
        sizes = " x ".join(f"{len(v)} {k}" for k, v in axes.items())
        raise InputError(
            f"{source}: [grid] {sizes}{f' x {len(cases)} [[cases]]' if len(cases) > 1 else ''} = {count} tasks: more "
            f"than the limit of {LIMITS['tasks']} tasks of one sweep; split the grid into smaller sweeps"
        )
    runs, seen = [], set()
    for i, case in enumerate(cases):
        where = f"[[cases]] {i + 1} " if "cases" in data else "[grid] "
        fixed = {k: _check_axis(source, where, k, v) for k, v in case.items()}
        both = sorted(set(fixed) & set(axes))
        if both:
            raise _err(source, where, both[0], case[both[0]], "a field not also in [grid]")
        for combo in itertools.product(*axes.values()):
            params = {**defaults, **fixed, **dict(zip(axes, combo))}
            if "load" not in params:
                raise _err(source, where, "load", None, "a load (in [grid] or in each [[cases]])")
            run = _resolve(params, problems, where)
            key = repr(sorted(run.params.items()))
            if key in seen:
                raise _err(source, where, "cases", params, "distinct runs (this one appears twice)")
            seen.add(key)
            runs.append(run)
    _check_sizes(runs, source)
    names = dict.fromkeys(k for r in runs for k in r.params)
    varied = tuple(k for k in names if len({repr(r.params.get(k)) for r in runs}) > 1)
    return SweepSpec(source, str(data.get("title", "")), tuple(runs), oracle, retries, cluster, varied)


def _check_sizes(runs, source: str) -> None:
    """One size estimate per distinct (mesh, truth mesh, duration, method) before any task runs."""
    seen = set()
    for run in runs:
        method = run.params["method"]
        key = (run.problem.nodes, run.truth_nodes, run.t_end, method)
        if key in seen:
            continue
        seen.add(key)
        samples = int(min(run.t_end / run.problem.identification.dt, 1e15)) + 1
        knobs = {
            "mesh": f'"mesh.nodes" {run.problem.nodes[0]}x{run.problem.nodes[1]}',
            "samples": f"t_end = {run.t_end:g}",
            "truth": f"truth_mesh = {run.truth_nodes[0]}x{run.truth_nodes[1]}",
        }
        est = resources.estimate_identify(
            run.problem.nodes, samples, truth_nodes=run.truth_nodes, method=method, knobs=knobs
        )
        try:
            resources.check(est)
        except InputError as exc:
            raise InputError(f"{source}: one task: {exc}") from None


def _resolve(params: dict, problems: _Problems, where: str) -> Run:
    truth_ov = {k[len("truth.") :]: v for k, v in params.items() if k.startswith("truth.")}
    est = {k[len("estimator.") :]: v for k, v in params.items() if k.startswith("estimator.")}
    both = {k: v for k, v in params.items() if k not in AXES and not k.startswith(("truth.", "estimator."))}
    problem = problems.get(both, where)
    truth = problems.get({**both, **truth_ov}, where)
    try:
        settings = MHESettings().replace(**est)
    except (InputError, TypeError, ValueError) as exc:
        raise InputError(f"{problems.source}: {where}estimator settings {est}: {exc}") from None
    return Run(params, problem, truth, settings, parse_mesh(params["truth_mesh"]), float(params["t_end"]))
