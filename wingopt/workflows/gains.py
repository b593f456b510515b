"""Full-order LQR gains of the plate on several meshes and their functional gains (``wingopt gains``).

The seed's evidence that the control law converges (eq. 5.29, Figs. 5.12–5.17): the feedback gain
of each mesh mapped back to fields, along the mid-chord line for PZ1, PZ4 and PZ7. The gains come
from Newton–Kleinman with low-rank ADI (:func:`wingopt.control.riccati_large.plate_lqr_gain`).
A cache directory keeps each mesh's gain (``gains_<mesh>.npz``, with ``r`` and the weight modes it
was computed for), so that the profiles and the figure can be redrawn without recomputing it.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wingopt.control.riccati_large import DEFAULT_WEIGHT_MODES, GAIN_R, gain_profiles, plate_lqr_gain
from wingopt.errors import InputError
from wingopt.plate import PlateModel
from wingopt.plots.morph import plot_functional_gains
from wingopt.problem import load_problem
from wingopt.results import ResultDirectory, check_writable, to_jsonable, write_arrays_atomic, write_csv, write_json

__all__ = ["GainsResult", "plate_gains", "write_gains_outputs", "gains_to_directory"]


@dataclass(frozen=True)
class GainsResult:
    """The gains of a run: ``summary`` (problem, ``r``, weight modes, one record per mesh) and
    ``profiles`` (mesh label -> :func:`~wingopt.control.riccati_large.gain_profiles`)."""

    summary: dict[str, Any]
    profiles: dict[str, dict]


def _cached_gain(path: Path | None, r: float, weight_modes: int, states: int) -> tuple[np.ndarray | None, dict]:
    """The gain in ``path`` and its record if it was computed for ``r``, ``weight_modes`` and ``states``."""
    if path is None or not path.exists():
        return None, {}
    data = np.load(path)
    if float(data["r"]) != r or int(data["weight_modes"]) != weight_modes or data["K"].shape[1] != states:
        return None, {}
    return data["K"], json.loads(str(data["info"])) if "info" in data.files else {}


def plate_gains(
    problem,
    meshes: list[tuple[int, int]],
    r: float | None = None,
    weight_modes: int | None = None,
    cache: str | Path | None = None,
) -> GainsResult:
    """The full-order continuous LQR gain of the plate ``problem`` on each mesh, and its profiles.

    ``r`` (input weight ``R = r I``, V^-2) defaults to :data:`~wingopt.control.riccati_large.GAIN_R`,
    ``weight_modes`` to :data:`~wingopt.control.riccati_large.DEFAULT_WEIGHT_MODES`. With ``cache``
    (a directory), a gain computed before for the same mesh, ``r`` and weight is reused
    (``cached: true`` in its record) and a new one is kept there.
    """
    r = GAIN_R if r is None else r
    wm = DEFAULT_WEIGHT_MODES if weight_modes is None else weight_modes
    if not (np.isfinite(r) and r > 0):
        raise InputError(f"r = {r!r}: expected a positive input weight")
    if wm < 1:
        raise InputError(f"weight-modes = {wm!r}: expected a positive number of modes")
    if not meshes:
        raise InputError("meshes: expected at least one mesh, e.g. 7x31,13x61")
    if problem.kind != "plate":
        raise InputError(f"problem = {problem.name!r}: gains needs a plate problem, got kind {problem.kind!r}")
    cache = Path(cache) if cache else None
    records, profiles = [], {}
    for nodes in meshes:
        label = f"{nodes[0]}x{nodes[1]}"
        model = PlateModel.from_problem(problem, nodes)
        rec = {"mesh": label, "dofs": model.n, "states": 2 * model.n}
        path = cache / f"gains_{label}.npz" if cache else None
        K, info = _cached_gain(path, r, wm, 2 * model.n)
        if K is not None:
            rec.update(info, cached=True)
        else:
            t0 = time.perf_counter()
            K, info = plate_lqr_gain(model, r, weight_modes=wm)
            rec.update(info, wall_s=time.perf_counter() - t0)
            if path is not None:
                write_arrays_atomic(path, K=K, r=r, weight_modes=wm, info=json.dumps(to_jsonable(rec)))
        profiles[label] = gain_profiles(model, K)
        records.append(rec)
    return GainsResult({"problem": problem.name, "r": r, "weight_modes": wm, "meshes": records}, profiles)


def write_gains_outputs(result: GainsResult, out: str | Path) -> None:
    """``summary.json``, ``profiles.csv`` (bending and velocity gain per patch and mesh along ``y``)
    and ``functional_gains.png`` into ``out``, replaced atomically."""
    profiles = result.profiles
    with ResultDirectory(out) as tmp:
        write_json(tmp / "summary.json", result.summary)
        header, cols = ["y"], [next(iter(profiles.values()))["y"]]
        for label, pr in profiles.items():
            for j, name in enumerate(pr["patches"]):
                header += [f"bending_{name}_{label}", f"velocity_{name}_{label}"]
                cols += [pr["bending"][j], pr["velocity"][j]]
        write_csv(tmp / "profiles.csv", header, np.column_stack(cols))
        plot_functional_gains(tmp / "functional_gains.png", profiles)


def gains_to_directory(
    problem: str | Path,
    meshes: list[tuple[int, int]],
    out: str | Path,
    r: float | None = None,
    weight_modes: int | None = None,
    cache: str | Path | None = None,
) -> dict:
    """The ``wingopt gains`` use case: read ``problem``, compute (or reuse) the gains, write ``out``.

    ``out`` is checked before any work. Returns the summary written.
    """
    check_writable(out)
    result = plate_gains(load_problem(problem), meshes, r, weight_modes, cache)
    write_gains_outputs(result, out)
    return result.summary
