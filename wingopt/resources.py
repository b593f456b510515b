"""Size estimates before work: refuse a run that cannot fit instead of dying halfway.

Every command makes one size estimate before it starts (issue 25): ``estimate_identify``,
``estimate_morph``, ``estimate_modes`` (any model build: ``modes``, ``gains``, ``design-sensors``,
``calibrate``), ``estimate_stream``, ``estimate_design`` and ``estimate_qp`` return an
:class:`Estimate` (memory in bytes, time in seconds, the terms that dominate and the option behind
each); :func:`check` raises an :class:`~wingopt.errors.InputError` naming the option of the largest
term when the memory exceeds what this process may use (``MemAvailable``, the address-space limit
``ulimit -v`` and the cgroup's limit, whichever is least) or a given limit (``--max-memory``), or
when the time exceeds :data:`MAX_SECONDS` (a day of CPU; :func:`long_runs`, ``wingopt morph
--force``, lets such a run start). Counts that multiply the work (tasks of a study grid,
seeds, Monte Carlo layouts, sensors) have limits of their own (:func:`check_count`), and so does
the size of what is read (:func:`check_input_file`). The formulas count the arrays that scale with the mesh and the
duration (trajectories, dense modal bases and covariances, sparse factorisations) plus the
interpreter's own ~150 MB; they were checked against the peak RSS of runs on small meshes (within
a factor 1.5: identify 25x13 from a 49x25 truth, 1 s: 233 MB measured; 4 s: 391 MB; 97x49 from a 25x13
truth: 902 MB). They are
meant to catch sizes that are off by orders of magnitude (a 2000x2000 mesh, ``t_end = 1e6``) in
well under a second, not to predict to the megabyte.
"""

from __future__ import annotations

import math
import os
import re
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field

from wingopt.errors import InputError
from wingopt.memory import BASE_BYTES, available_memory

__all__ = [
    "Estimate",
    "estimate_identify",
    "estimate_morph",
    "estimate_modes",
    "estimate_stream",
    "estimate_design",
    "estimate_qp",
    "available_memory",
    "check",
    "check_count",
    "check_input_file",
    "parse_size",
    "LIMITS",
    "MAX_SECONDS",
    "long_runs",
]


_F = 8.0  # bytes per float64
_JEKF_RUNS = {"jekf-seed": 23}
"""Filter runs a JEKF's lambda costs (the tuned rule's grid: 20; the seed's Nelder-Mead a few more)."""


@dataclass(frozen=True)
class Estimate:
    """Memory (bytes) and time (s) a run will need, and the terms behind them.

    ``knobs``: the option that sets each term (``{"truth trajectory": "--t-end 1e9"}``), named by
    :func:`check` when it refuses.
    """

    what: str
    memory: float
    seconds: float
    terms: dict[str, float] = field(default_factory=dict)
    knobs: dict[str, str] = field(default_factory=dict)

    @property
    def top(self) -> str:
        return max(self.terms, key=self.terms.get) if self.terms else "total"

    def describe(self) -> str:
        return f"{self.what} needs about {fmt_bytes(self.memory)} (mostly {self.top}) and {fmt_seconds(self.seconds)}"

    def knob(self) -> str | None:
        """The option behind the largest term (``None`` if not known)."""
        return self.knobs.get(self.top)


LIMITS = {
    "tasks": 100_000,
    "seeds": 10_000,
    "montecarlo": 1_000,
    "nominal": 1_000,
    "sensors": 1_000,
    "count": 1_000,
    "modes": 10_000,
    "meshes": 20,
}
"""Counts that multiply the work: a study's tasks (grid x cases), noise seeds, Monte Carlo layouts,
nominal loads, sensors of a problem, sensors to design, modes asked for, meshes of ``gains``."""

MAX_SECONDS = 86400.0
"""A run estimated to take longer than a day of CPU is refused (it would be stopped long before),
unless long runs are allowed (:func:`long_runs`: ``wingopt morph --force``)."""

_LONG_RUNS: ContextVar[tuple[bool, str | None]] = ContextVar("wingopt_long_runs", default=(False, None))


@contextmanager
def long_runs(allowed: bool = True, option: str | None = None):
    """Within this block :func:`check` lets a run estimated beyond :data:`MAX_SECONDS` start
    (``allowed``), or names ``option`` (``"--force"``) as the way to allow one it refuses."""
    token = _LONG_RUNS.set((bool(allowed), option))
    try:
        yield
    finally:
        _LONG_RUNS.reset(token)


MAX_TEXT_BYTES = 1 << 20
"""Largest problem file or sweep spec read (1 MiB: a problem file is a few kB)."""


def fmt_bytes(b: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if b >= scale:
            return f"{b / scale:.3g} {unit}"
    return f"{b / 1e3:.3g} kB"


def fmt_seconds(s: float) -> str:
    if s >= 86400:
        days = f"{s / 86400:.3g}"
        return f"{days} day" + ("" if days == "1" else "s")
    if s >= 3600:
        return f"{s / 3600:.3g} h"
    if s >= 60:
        return f"{s / 60:.3g} min"
    return f"{s:.2g} s"


def parse_size(text: str) -> float:
    """``"4G"``, ``"500MB"``, ``"2e9"`` -> bytes."""
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*([kKmMgGtT]?)[bB]?\s*", str(text))
    if not m:
        raise InputError(f"max-memory = {text!r}: expected a size such as 4G, 500M or 2e9 (bytes)")
    value = float(m.group(1)) * {"": 1, "k": 1e3, "m": 1e6, "g": 1e9, "t": 1e12}[m.group(2).lower()]
    if not value > 0:
        raise InputError(f"max-memory = {text!r}: expected a positive size")
    return value


def _lu_bytes(n: float) -> float:
    # sparse LU of a 2-D cubic-spline operator (49 entries a row): fill ~ 100 n log2 n entries (nested dissection)
    return _F * 1.5 * 100.0 * n * max(1.0, math.log2(max(n, 2.0)))


def membrane_dofs(nodes: tuple[int, int]) -> int:
    """Coefficients of the membrane's deflection: ``nx ny`` (checked against ``MembraneModel.n``)."""
    return int(nodes[0]) * int(nodes[1])


def plate_dofs(nodes: tuple[int, int]) -> int:
    """Coefficients of the plate's deflection: ``(nx + 2) ny`` (checked against ``PlateModel.n``)."""
    return (int(nodes[0]) + 2) * int(nodes[1])


def _mesh(nodes) -> str:
    return f"{int(nodes[0])}x{int(nodes[1])}"


def estimate_modes(nodes: tuple[int, int], kind: str = "membrane", knob: str = "--mesh") -> Estimate:
    """Memory and time of building the FE model (and a few modes) on ``nodes``."""
    n = membrane_dofs(nodes) if kind == "membrane" else plate_dofs(nodes)
    terms = {"sparse factorisation": _lu_bytes(n), "operators": _F * 1.5 * 49 * 4 * n}
    mem = BASE_BYTES + sum(terms.values())
    label = f"{knob} {_mesh(nodes)}"
    return Estimate(
        f"{kind} model {_mesh(nodes)} ({n} dofs)",
        mem,
        1.0 + 2e-6 * n * math.log2(max(n, 2)),
        terms,
        dict.fromkeys(terms, label),
    )


def estimate_identify(
    nodes: tuple[int, int],
    samples: int,
    *,
    truth_nodes: tuple[int, int] | None = None,
    method: str = "mhe",
    modes: int = 40,
    knobs: dict[str, str] | None = None,
    jekf_modes: int | None = None,
) -> Estimate:
    """Memory and time of ``identify`` on an estimator mesh ``nodes`` for ``samples`` samples.

    ``truth_nodes``: the simulated protocol's truth mesh (its full modal basis is dense and its
    trajectory is stored); ``None`` for measured data. ``knobs``: the options behind ``"mesh"``,
    ``"samples"`` and ``"truth"`` (default the ``identify`` flags). ``jekf_modes``: a JEKF's order
    (its lowest modes; ``None``: every mode).
    """
    k = {"mesh": f"--mesh {_mesh(nodes)}", "samples": "--t-end (the record's length)", "truth": "--truth-mesh"}
    if truth_nodes is not None:
        k["truth"] = f"--truth-mesh {_mesh(truth_nodes)}"
    k.update(knobs or {})
    n = membrane_dofs(nodes)
    N = max(int(samples), 1)
    m = max(1, min(int(modes), n))
    terms: dict[str, float] = {
        "estimator factorisation": _lu_bytes(n),
        # dense n x n operators of the MHE set-up (97x49, n = 4753: 902 MB peak measured, 0.95x this)
        "dense estimator operators": 5 * _F * n * n,
        "estimate histories (load, deflection per sample)": 2 * _F * N * n + 2 * _F * N * m,
    }
    knob = {
        "estimator factorisation": k["mesh"],
        "dense estimator operators": k["mesh"],
        "estimate histories (load, deflection per sample)": k["samples"],
    }
    seconds = 2.0 + 5e-4 * N * (1 + n / 2000) + 1e-9 * n**3
    if truth_nodes is not None:
        nt = membrane_dofs(truth_nodes)
        terms["truth modal basis (dense)"] = 4 * _F * nt * nt
        terms["truth trajectory"] = 5 * _F * N * nt
        knob["truth modal basis (dense)"] = k["truth"]
        knob["truth trajectory"] = k["samples"] if 5 * N > 4 * nt else k["truth"]
        seconds += 1e-9 * nt**3 + 2e-8 * N * nt
    if method.startswith("jekf"):
        r = n if jekf_modes is None else max(1, min(int(jekf_modes), n))
        terms["JEKF covariance (dense)"] = 6 * _F * (3 * r) ** 2
        knob["JEKF covariance (dense)"] = k["mesh"] if jekf_modes is None else "--jekf-order"
        # The modal filter: O((3r)^2) per sample (block-diagonal transition, rank-2p update), about 20
        # filter runs for lambda (the tuned rule's grid; the seed's Nelder-Mead a few more). Measured on
        # 25x13, 1001 samples, CPU: tuned 2.4 s at 60 modes, 59 s with every mode (325); seed 3.9 s, 67 s.
        seconds += _JEKF_RUNS.get(method, 20) * 4e-9 * N * (3 * r) ** 2
    where = f"identify on {_mesh(nodes)} ({n} dofs), {N} samples"
    return Estimate(where, BASE_BYTES + sum(terms.values()), seconds, terms, knob)


def estimate_stream(nodes: tuple[int, int], sensors: int, knob: str = "--mesh") -> Estimate:
    """Memory and time (per sample) of a streaming estimator on ``nodes`` with ``sensors`` sensors."""
    n = membrane_dofs(nodes)
    terms = {
        "model factorisation": _lu_bytes(n),
        "dense modal basis": 2 * _F * n * min(n, 200),
        "sensor operators": _F * sensors * n,
    }
    knobs = {"model factorisation": f"{knob} {_mesh(nodes)}", "dense modal basis": f"{knob} {_mesh(nodes)}"}
    knobs["sensor operators"] = "[[sensors]]"
    return Estimate(
        f"a stream on {_mesh(nodes)} ({n} dofs)", BASE_BYTES + sum(terms.values()), 2.0 + 1e-9 * n**2, terms, knobs
    )


def estimate_morph(
    nodes: tuple[int, int],
    t_end: float,
    period: float,
    plant_dt: float | None = None,
    horizon: int | None = None,
    inputs: int = 9,
) -> Estimate:
    """Memory and time of ``morph`` on the plate mesh ``nodes`` for ``t_end`` s (``horizon``: the QP's)."""
    n = plate_dofs(nodes)
    steps = max(int(t_end / (plant_dt or period)), 1) if period > 0 and t_end > 0 else 1
    dense = n <= 1000  # closed_loop.DENSE_PLANT_MAX_DOFS
    terms = {
        "trajectories (deflection, velocity per step)": 2 * _F * steps * n,
        # 13x61 LQR, 0.5 s: 397 MB peak measured, 1.06x this
        "plant": 6 * _F * (2 * n) ** 2 if dense else _lu_bytes(n) + 2 * _F * n * 200,
        "controller (dense Riccati)": 4 * _F * (2 * min(n, 1000)) ** 2,
    }
    knobs = {
        "trajectories (deflection, velocity per step)": f"--t-end {t_end:g} / --period {period:g}",
        "plant": f"--mesh {_mesh(nodes)}",
        "controller (dense Riccati)": f"--mesh {_mesh(nodes)}",
    }
    seconds = 5.0 + 4e-9 * (2 * n) ** 3 * (1 if dense else 0.1) + steps * (2e-3 + 2e-7 * n)
    if horizon:
        H = int(horizon)
        states = 2 * min(n, 1000)
        # condensed QP: prediction matrices (states x inputs H per step) and the Hessian (inputs H)^2
        terms["QP (condensed over the horizon)"] = _F * (H * states * inputs * 2 + 3 * (inputs * H) ** 2)
        knobs["QP (condensed over the horizon)"] = f"--horizon {H}"
        seconds += steps * 1e-9 * (inputs * H) ** 3 / 100
    where = f"morph on {_mesh(nodes)} ({n} dofs), {steps} steps"
    return Estimate(where, BASE_BYTES + sum(terms.values()), seconds, terms, knobs)


def estimate_qp(horizon: int, states: int, inputs: int) -> Estimate:
    """Memory of one condensed MPC problem (``horizon`` steps)."""
    H = int(horizon)
    terms = {"QP (condensed over the horizon)": _F * (H * states * inputs * 2 + 3 * (inputs * H) ** 2)}
    return Estimate(
        f"a QP over {H} steps",
        BASE_BYTES + sum(terms.values()),
        1e-9 * (inputs * H) ** 3,
        terms,
        {"QP (condensed over the horizon)": f"--horizon {H}"},
    )


def estimate_design(
    nodes: tuple[int, int], candidates: int, nominal: int, count: int, montecarlo: int = 0, samples: int = 1000
) -> Estimate:
    """Memory and time of ``design-sensors``: the model, one information matrix per candidate and
    nominal load (modes x modes), the relaxation over the candidates, the Monte Carlo re-ranking."""
    n = membrane_dofs(nodes)
    m = min(n, 60)
    terms = {
        "model": _lu_bytes(n) + 2 * _F * n * m,
        "candidate information (candidates x nominal loads)": _F * candidates * max(nominal, 1) * m * 4,
        "relaxation": _F * candidates * m * m / 4,
    }
    knobs = {
        "model": f"mesh {_mesh(nodes)}",
        "candidate information (candidates x nominal loads)": f"--nominal {nominal}",
        "relaxation": "--candidates",
    }
    seconds = 2.0 + 1e-9 * n**2 + 2e-6 * candidates * max(nominal, 1) * m + 1e-3 * candidates * count
    seconds += montecarlo * 8 * max(nominal, 1) * (1.0 + 5e-4 * samples)
    if montecarlo:
        knobs["montecarlo"] = f"--montecarlo {montecarlo}"
    return Estimate(
        f"design-sensors on {_mesh(nodes)} ({candidates} candidates)",
        BASE_BYTES + sum(terms.values()),
        seconds,
        terms,
        knobs,
    )


SAFETY = 0.5
"""Share of the available memory a run may plan for by default: the estimates are good to ~1.5x and
other processes grow too (a morph of 1e4 s, 15 GB, would otherwise start on a 24 GB machine)."""


def check(estimate: Estimate, max_memory: float | None = None) -> Estimate:
    """Raise :class:`InputError` (naming the option behind the largest term, with the estimate) if
    the run cannot fit in memory or would take longer than :data:`MAX_SECONDS` (unless allowed by
    :func:`long_runs`).

    The memory limit is ``max_memory`` when given, else :data:`SAFETY` times :func:`available_memory`.
    """
    limit = SAFETY * available_memory() if max_memory is None else float(max_memory)
    knob = estimate.knob()
    lead = f"{knob}: " if knob else ""
    advice = f"give a smaller {knob.split()[0]}" if knob else "use a coarser mesh or a shorter duration"
    if estimate.memory > limit:
        what = "half the memory available" if max_memory is None else "--max-memory"
        raise InputError(f"{lead}{estimate.describe()}: more than {what} ({fmt_bytes(limit)}); {advice}")
    allowed, option = _LONG_RUNS.get()
    if estimate.seconds > MAX_SECONDS and not allowed:
        hint = f", or {option} to run it anyway" if option else ""
        raise InputError(
            f"{lead}{estimate.describe()}: longer than the limit of {fmt_seconds(MAX_SECONDS)}; {advice}{hint}"
        )
    return estimate


def check_count(name: str, value, limit_key: str | None = None, *, what: str = "") -> int:
    """``value`` a whole number from 1 to ``LIMITS[limit_key]`` (an :class:`InputError` naming ``name``)."""
    limit = LIMITS[limit_key or name.lstrip("-").replace("-", "_")]
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{name} = {value!r}: expected a whole number")
    if value > limit:
        raise InputError(
            f"{name} = {value}: more than the limit of {limit}{' ' + what if what else ''}; "
            "split the work into smaller runs"
        )
    return value


def check_input_file(path, what: str, limit: int = MAX_TEXT_BYTES) -> None:
    """Refuse, before reading it, an input that is not a regular file or is larger than ``limit``."""
    import stat

    try:
        st = os.stat(path)
    except OSError:
        return  # the reader says what is wrong with it
    if not stat.S_ISREG(st.st_mode):
        kind = "a directory" if stat.S_ISDIR(st.st_mode) else "not a regular file (a device, a pipe)"
        raise InputError(f"{what} = {str(path)!r}: is {kind}; expected a text file")
    if st.st_size > limit:
        raise InputError(
            f"{what} = {str(path)!r}: {fmt_bytes(st.st_size)}, more than the {fmt_bytes(limit)} such a file may "
            "have (a problem file or spec is a few kB)"
        )
