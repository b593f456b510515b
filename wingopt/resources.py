"""Size estimates before work: refuse a run that cannot fit instead of dying halfway.

``estimate_identify`` and ``estimate_morph`` return an :class:`Estimate` (memory in bytes, time in
seconds, the terms that dominate); :func:`check` raises an :class:`~wingopt.errors.InputError`
with the estimate when the memory exceeds what the machine has available (``MemAvailable``) or a
given limit (``--max-memory``). The formulas count the arrays that scale with the mesh and the
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
from dataclasses import dataclass, field

from wingopt.errors import InputError

__all__ = [
    "Estimate",
    "estimate_identify",
    "estimate_morph",
    "estimate_modes",
    "available_memory",
    "check",
    "parse_size",
]

BASE_BYTES = 150e6
"""Interpreter, numpy/scipy/cvxpy imports and small arrays (measured ~150 MB)."""

_F = 8.0  # bytes per float64


@dataclass(frozen=True)
class Estimate:
    """Memory (bytes) and time (s) a run will need, and the terms behind them."""

    what: str
    memory: float
    seconds: float
    terms: dict[str, float] = field(default_factory=dict)

    def describe(self) -> str:
        top = max(self.terms, key=self.terms.get) if self.terms else "total"
        return f"{self.what} needs about {fmt_bytes(self.memory)} (mostly {top}) and {fmt_seconds(self.seconds)}"


def fmt_bytes(b: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if b >= scale:
            return f"{b / scale:.3g} {unit}"
    return f"{b / 1e3:.3g} kB"


def fmt_seconds(s: float) -> str:
    if s >= 86400:
        return f"{s / 86400:.3g} days"
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


def available_memory() -> float:
    """Bytes the machine can give now (``MemAvailable``; total physical memory where unknown)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return float("inf")


def _lu_bytes(n: float) -> float:
    # sparse LU of a 2-D cubic-spline operator (49 entries a row): fill ~ 100 n log2 n entries (nested dissection)
    return _F * 1.5 * 100.0 * n * max(1.0, math.log2(max(n, 2.0)))


def membrane_dofs(nodes: tuple[int, int]) -> int:
    """Coefficients of the membrane's deflection: ``nx ny`` (checked against ``MembraneModel.n``)."""
    return int(nodes[0]) * int(nodes[1])


def plate_dofs(nodes: tuple[int, int]) -> int:
    """Coefficients of the plate's deflection: ``(nx + 2) ny`` (checked against ``PlateModel.n``)."""
    return (int(nodes[0]) + 2) * int(nodes[1])


def estimate_modes(nodes: tuple[int, int], kind: str = "membrane") -> Estimate:
    n = membrane_dofs(nodes) if kind == "membrane" else plate_dofs(nodes)
    terms = {"sparse factorisation": _lu_bytes(n), "operators": _F * 1.5 * 49 * 4 * n}
    mem = BASE_BYTES + sum(terms.values())
    return Estimate(f"{kind} model {nodes[0]}x{nodes[1]} ({n} dofs)", mem, 1.0 + 2e-6 * n * math.log2(max(n, 2)), terms)


def estimate_identify(
    nodes: tuple[int, int],
    samples: int,
    *,
    truth_nodes: tuple[int, int] | None = None,
    method: str = "mhe",
    modes: int = 40,
) -> Estimate:
    """Memory and time of ``identify`` on an estimator mesh ``nodes`` for ``samples`` samples.

    ``truth_nodes``: the simulated protocol's truth mesh (its full modal basis is dense and its
    trajectory is stored); ``None`` for measured data.
    """
    n = membrane_dofs(nodes)
    N = max(int(samples), 1)
    terms: dict[str, float] = {
        "estimator factorisation": _lu_bytes(n),
        # dense n x n operators of the MHE set-up (97x49, n = 4753: 902 MB peak measured, 0.95x this)
        "dense estimator operators": 5 * _F * n * n,
        "estimate histories (load, deflection per sample)": 2 * _F * N * n + 2 * _F * N * modes,
    }
    seconds = 2.0 + 5e-4 * N * (1 + n / 2000) + 1e-9 * n**3
    if truth_nodes is not None:
        nt = membrane_dofs(truth_nodes)
        terms["truth modal basis (dense)"] = 4 * _F * nt * nt
        terms["truth trajectory"] = 5 * _F * N * nt
        seconds += 1e-9 * nt**3 + 2e-8 * N * nt
    if method.startswith("jekf"):
        terms["JEKF covariance (dense)"] = 6 * _F * (3 * n) ** 2
        # a dense covariance update per sample, O((3n)^3); the seed's lambda search runs the filter again
        seconds += 1e-10 * N * (3 * n) ** 3 * (2 if method == "jekf-seed" else 1)
    where = f"identify on {nodes[0]}x{nodes[1]} ({n} dofs), {N} samples"
    return Estimate(where, BASE_BYTES + sum(terms.values()), seconds, terms)


def estimate_morph(nodes: tuple[int, int], t_end: float, period: float, plant_dt: float | None = None) -> Estimate:
    """Memory and time of ``morph`` on the plate mesh ``nodes`` for ``t_end`` s."""
    n = plate_dofs(nodes)
    steps = max(int(t_end / (plant_dt or period)), 1)
    dense = n <= 1000  # closed_loop.DENSE_PLANT_MAX_DOFS
    terms = {
        "trajectories (deflection, velocity per step)": 2 * _F * steps * n,
        # 13x61 LQR, 0.5 s: 397 MB peak measured, 1.06x this
        "plant": 6 * _F * (2 * n) ** 2 if dense else _lu_bytes(n) + 2 * _F * n * 200,
        "controller (dense Riccati)": 4 * _F * (2 * min(n, 1000)) ** 2,
    }
    seconds = 5.0 + 4e-9 * (2 * n) ** 3 * (1 if dense else 0.1) + steps * (2e-3 + 2e-7 * n)
    where = f"morph on {nodes[0]}x{nodes[1]} ({n} dofs), {steps} steps"
    return Estimate(where, BASE_BYTES + sum(terms.values()), seconds, terms)


SAFETY = 0.5
"""Share of the available memory a run may plan for by default: the estimates are good to ~1.5x and
other processes grow too (a morph of 1e4 s, 15 GB, would otherwise start on a 24 GB machine)."""


def check(estimate: Estimate, max_memory: float | None = None) -> Estimate:
    """Raise :class:`InputError` (with the estimate) if the run cannot fit in memory.

    The limit is ``max_memory`` when given, else :data:`SAFETY` times the memory available now.
    """
    limit = SAFETY * available_memory() if max_memory is None else float(max_memory)
    if estimate.memory > limit:
        what = "half the memory available" if max_memory is None else "--max-memory"
        raise InputError(
            f"{estimate.describe()}: more than {what} ({fmt_bytes(limit)}); use a coarser mesh or a shorter duration"
        )
    return estimate
