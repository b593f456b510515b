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
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wingopt import resources
from wingopt.control.riccati_large import DEFAULT_WEIGHT_MODES, GAIN_R, gain_profiles, plate_lqr_gain
from wingopt.errors import InputError
from wingopt.plate import PlateModel
from wingopt.plots.morph import plot_functional_gains
from wingopt.problem import as_problem, load_problem
from wingopt.resources import check_count
from wingopt.results import OwnedDirectory, ResultDirectory, check_writable, to_jsonable, write_csv, write_json
from wingopt.status import RunStatus, from_info, worst
from wingopt.validate import check_nodes, check_number

__all__ = ["GainsResult", "plate_gains", "write_gains_outputs", "gains_to_directory"]


@dataclass(frozen=True)
class GainsResult:
    """The gains of a run: ``summary`` (problem, ``r``, weight modes, one record per mesh) and
    ``profiles`` (mesh label -> :func:`~wingopt.control.riccati_large.gain_profiles`)."""

    summary: dict[str, Any]
    profiles: dict[str, dict]

    @property
    def status(self) -> RunStatus:
        """The worst of the meshes' :class:`~wingopt.status.RunStatus` (``summary["status"]``)."""
        return RunStatus(self.summary["status"])

    def __repr__(self) -> str:
        # The profiles hold every gain curve; the summary's key numbers are enough to recognise a run.
        meshes = ", ".join(f"{m['mesh']} ({m['dofs']} dofs)" for m in self.summary["meshes"])
        return (
            f"GainsResult(problem={self.summary['problem']!r}, r={self.summary['r']:.3g}, meshes=[{meshes}], "
            f"status='{self.status}')"
        )


def _cached_gain(cache, name: str, r: float, weight_modes: int, states: int) -> tuple[np.ndarray | None, dict]:
    """The gain ``name`` of the cache (an :class:`~wingopt.results.OwnedDirectory`) and its record if
    wingopt wrote it there, unchanged, for ``r``, ``weight_modes`` and ``states``."""
    if cache is None or not cache.owns(name):
        return None, {}
    try:
        with np.load(cache.path / name, allow_pickle=False) as data:
            if float(data["r"]) != r or int(data["weight_modes"]) != weight_modes or data["K"].shape[1] != states:
                return None, {}
            return np.array(data["K"]), json.loads(str(data["info"])) if "info" in data.files else {}
    except (OSError, ValueError, KeyError, IndexError, EOFError, zipfile.BadZipFile) as exc:
        raise InputError(f"cache = {str(cache.given)!r}: {name} cannot be read ({type(exc).__name__}: {exc})") from None


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
    r = GAIN_R if r is None else check_number("r", r, positive=True)
    wm = DEFAULT_WEIGHT_MODES if weight_modes is None else weight_modes
    if not (np.isfinite(r) and 1e-30 <= r <= 1e10):
        raise InputError(f"r = {r!r}: expected an input weight from 1e-30 to 1e10 (V^-2; default {GAIN_R:g})")
    if isinstance(wm, bool) or not isinstance(wm, int) or wm < 1:
        raise InputError(f"weight-modes = {wm!r}: expected a positive number of modes")
    check_count("weight-modes", wm, "modes")
    if isinstance(meshes, (str, bytes)) or not meshes:
        raise InputError(f"meshes = {meshes!r}: expected at least one mesh (nx, ny), e.g. [(7, 31), (13, 61)]")
    meshes = [check_nodes(m, "meshes") for m in meshes]
    check_count("meshes", len(meshes))
    problem = as_problem(problem, "plate")
    for nodes in meshes:  # every mesh's size before the first gain
        resources.check(resources.estimate_modes(nodes, "plate", knob="--meshes"))
    if cache is not None and not isinstance(cache, OwnedDirectory):
        cache = OwnedDirectory(cache, what="cache") if cache else None
    records, profiles = [], {}
    for nodes in meshes:
        label = f"{nodes[0]}x{nodes[1]}"
        model = PlateModel.from_problem(problem, nodes)
        rec = {"mesh": label, "dofs": model.n, "states": 2 * model.n}
        name = f"gains_{label}.npz"
        if cache is not None and (cache.path / name).exists() and not cache.owns(name):
            raise InputError(
                f"cache = {cache.given!r}: holds {name!r}, which wingopt did not write (or which changed since); "
                "wingopt neither reads nor replaces it: move it away or give another --cache"
            )
        K, info = _cached_gain(cache, name, r, wm, 2 * model.n)
        if K is not None:
            rec.update(info, cached=True)
        else:
            t0 = time.perf_counter()
            K, info = plate_lqr_gain(model, r, weight_modes=wm)
            rec.update(info, wall_s=time.perf_counter() - t0)
            if cache is not None:
                arrays = {"K": K, "r": r, "weight_modes": wm, "info": json.dumps(to_jsonable(rec))}
                cache.write(name, lambda tmp, a=arrays: _savez(tmp, a))
        profiles[label] = gain_profiles(model, K)
        # A gain from an iteration that stopped short (nk-adi's converged flag) is usable but not the
        # Riccati solution; one with NaN is none.
        bad = not np.all(np.isfinite(K))
        rec["status"] = str(RunStatus.FAILED if bad else from_info({"converged": rec.get("converged")}))
        records.append(rec)
    status = str(worst(*(RunStatus(rec["status"]) for rec in records)))
    summary = {"problem": problem.name, "status": status, "r": r, "weight_modes": wm, "meshes": records}
    return GainsResult(summary, profiles)


def _savez(path: Path, arrays: dict) -> None:
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


def write_gains_outputs(result: GainsResult, out: str | Path, inputs=()) -> None:
    """``summary.json``, ``profiles.csv`` (bending and velocity gain per patch and mesh along ``y``)
    and ``functional_gains.png`` into ``out``, replaced atomically."""
    if not isinstance(result, GainsResult):
        raise InputError(f"result = {type(result).__name__}: expected the GainsResult of plate_gains")
    profiles = result.profiles
    with ResultDirectory(out, inputs=inputs) as tmp:
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

    ``out`` and ``cache`` are checked before any work (:mod:`wingopt.results.ownership`: each may
    hold only what wingopt wrote there; a gain file of yours in the cache is neither read nor
    replaced). Returns the summary written.
    """
    inputs = [("problem", str(problem))] if isinstance(problem, (str, Path)) else []
    check_writable(out, inputs=inputs)
    owned = OwnedDirectory(cache, what="cache", inputs=inputs) if cache else None
    if owned is not None and (owned.path == Path(out).expanduser().resolve()):
        raise InputError(f"cache = {str(cache)!r}: the same directory as --out; give another")
    result = plate_gains(load_problem(problem), meshes, r, weight_modes, owned)
    write_gains_outputs(result, out, inputs)
    return result.summary
