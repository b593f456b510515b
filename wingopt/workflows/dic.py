"""DIC frames in: read them as the problem file declares, emulate stretch sensors, hand them to identify.

* :func:`read_frames`: a frame set (an ``.npz`` file, a directory of DICe solution files or of CSV
  frames) mapped to the wing by the problem's ``[dic]`` table (:mod:`wingopt.problem.dic`);
* :func:`dic_sensors` / :func:`write_dic_sensors_outputs`: the ``wingopt dic-sensors`` use case —
  virtual stretch sensors (:mod:`wingopt.membrane.virtual_sensors`, the slope route by default) as
  a CSV record ``wingopt identify --data`` reads, the first frame's shape beside it;
* :func:`dic_record`: what ``wingopt identify --dic`` needs — the frames, their virtual sensors, the
  problem with the first frame's shape as the prior initial deflection, and the report for
  ``summary.json``.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wingopt.errors import InputError
from wingopt.measurements import Measurements
from wingopt.measurements.dic import DICFrames
from wingopt.measurements.dic_npz import read_dic
from wingopt.membrane import MembraneModel
from wingopt.membrane.dic_fit import fit_frames
from wingopt.membrane.virtual_sensors import KINDS, METHODS, virtual_sensors
from wingopt.problem import load_problem
from wingopt.problem.dic import DICSettings
from wingopt.results import ResultDirectory, to_jsonable, write_csv, write_json

__all__ = ["read_frames", "DICSensorsRun", "dic_sensors", "write_dic_sensors_outputs", "dic_record", "SHAPE_GRID"]

log = logging.getLogger(__name__)

SHAPE_GRID = (57, 29)
"""Points (x, y) of the uniform grid of ``initial_shape.csv``, edges included."""


def read_frames(problem, source: str | Path | DICFrames) -> DICFrames:
    """The DIC frames of ``source`` mapped to ``problem``'s wing by its ``[dic]`` table (default: the wing's
    own frame in metres, which the NPZ layout always is)."""
    if isinstance(source, DICFrames):
        return source
    d = problem.dic or DICSettings()
    return read_dic(
        source,
        (problem.width, problem.height),
        mapping=d.mapping,
        frame_rate=d.frame_rate,
        strain_reference=d.strain_reference,
        strain_kind=d.strain_kind,
    )


def first_shape(frames: DICFrames, model: MembraneModel) -> tuple[int, np.ndarray]:
    """The first frame with a fit and its deflection coefficients on ``model``'s mesh."""
    head = frames.valid.mean(axis=1) >= 0.5
    if not head.any():
        raise InputError(f"{frames.source or 'DIC frames'}: no frame has half its points valid")
    k = int(np.argmax(head))
    one = dataclasses.replace(
        frames,
        t=frames.t[k : k + 1],
        valid=frames.valid[k : k + 1],
        **{
            f: None if getattr(frames, f) is None else getattr(frames, f)[k : k + 1]
            for f in ("u", "v", "w", "exx", "eyy", "exy")
        },
    )
    return k, fit_frames(one, one.w, model.space).coef[0]


@dataclass(eq=False)
class DICSensorsRun:
    """Virtual sensors from a DIC frame set and what was read."""

    problem: Any
    source: str
    frames: DICFrames
    measurements: Measurements
    kind: str
    method: str
    shape_frame: int
    shape: np.ndarray
    model: MembraneModel
    wall_s: float

    @property
    def peak(self) -> float:
        """The first frame's deflection of largest magnitude (signed, m)."""
        xs = np.linspace(0, self.problem.width, SHAPE_GRID[0])
        ys = np.linspace(0, self.problem.height, SHAPE_GRID[1])
        X, Y = np.meshgrid(xs, ys)
        w = self.model.field(self.shape)(X, Y)
        return float(w.ravel()[np.argmax(np.abs(w))])

    def report(self) -> dict:
        """The DIC part of ``summary.json``: route, frames, dropped points, the initial shape."""
        m = self.measurements
        return {
            "frames_source": self.source,
            "route": f"virtual sensors ({self.kind}, {self.method})",
            "read": None if self.frames.report is None else self.frames.report.as_dict(),
            "frames": self.frames.n_frames,
            "points": self.frames.n_points,
            "valid_fraction": self.frames.valid_fraction,
            "strain_kind": self.frames.strain_kind,
            "sensor_noise_std": None if m.noise_std is None else np.asarray(m.noise_std).tolist(),
            "initial_shape": {
                "frame": self.shape_frame,
                "t_s": float(self.frames.t[self.shape_frame]),
                "peak_m": self.peak,
                "mesh": list(self.problem.nodes),
            },
        }

    def summary(self) -> dict:
        return {
            "problem": self.problem.name,
            "dic": self.report(),
            "sensors": list(self.measurements.sensor_names),
            "samples": int(self.measurements.count),
            "wall_s": self.wall_s,
        }


def dic_sensors(problem, frames, *, kind: str = "slope", method: str = "fit") -> DICSensorsRun:
    """Emulate ``problem``'s stretch sensors from the DIC frames ``frames`` (a path or :class:`DICFrames`)."""
    if isinstance(problem, (str, Path)):
        problem = load_problem(problem)
    if getattr(problem, "kind", None) != "membrane":
        raise InputError(f"problem: DIC frames need a membrane problem, got kind {getattr(problem, 'kind', None)!r}")
    if kind not in KINDS or method not in METHODS:
        raise InputError(f"kind = {kind!r}, method = {method!r}: expected kind in {KINDS} and method in {METHODS}")
    if not problem.sensors:
        raise InputError(f"problem {problem.name!r}: no [[sensors]]: virtual sensors emulate the problem's sensors")
    t0 = time.perf_counter()
    fr = read_frames(problem, frames)
    meas = virtual_sensors(fr, problem, kind=kind, method=method)
    model = MembraneModel.from_problem(problem)
    k, z0 = first_shape(fr, model)
    src = str(frames) if not isinstance(frames, DICFrames) else (frames.source or "DIC frames")
    return DICSensorsRun(problem, src, fr, meas, kind, method, k, z0, model, time.perf_counter() - t0)


def write_dic_sensors_outputs(run: DICSensorsRun, out_dir: str | Path) -> Path:
    """``sensors.csv`` (``t`` + one column per sensor: ``wingopt identify --data`` reads it), ``initial_shape.csv``
    (the first frame's fitted deflection on a grid, edges included) and ``summary.json``, atomically."""
    m = run.measurements
    xs = np.linspace(0, run.problem.width, SHAPE_GRID[0])
    ys = np.linspace(0, run.problem.height, SHAPE_GRID[1])
    X, Y = np.meshgrid(xs, ys)
    W = run.model.field(run.shape)(X, Y)
    with ResultDirectory(out_dir) as tmp:
        write_csv(
            tmp / "sensors.csv", ["t", *m.sensor_names], (np.concatenate([[t], row]) for t, row in zip(m.t, m.values))
        )
        write_csv(tmp / "initial_shape.csv", ["x", "y", "w_m"], zip(X.ravel(), Y.ravel(), W.ravel()))
        write_json(tmp / "summary.json", to_jsonable(run.summary()))
    return Path(out_dir)


def dic_record(problem, frames, full_field: bool) -> tuple[Any, DICFrames, Measurements, dict]:
    """``identify --dic``: the problem (the first frame's signed peak as its prior initial deflection,
    unless the file states one), the frames, their virtual sensors (slope route) and the report.

    ``full_field``: the frames themselves are the data (the full-field estimator); otherwise their
    virtual sensors are.
    """
    run = dic_sensors(problem, frames)
    problem, ident = run.problem, run.problem.identification
    report = run.report()
    report["route"] = "full field (every point's deflection)" if full_field else report["route"]
    if not full_field and ident.initial_deflection == 0:
        peak = run.peak
        load = abs(ident.initial_load) * (1.0 if peak >= 0 else -1.0)
        problem = dataclasses.replace(
            problem, identification=dataclasses.replace(ident, initial_deflection=peak, initial_load=load)
        )
        report["initial_shape"]["used_as"] = "the prior initial deflection (its peak and sign)"
    return problem, run.frames, run.measurements, report
