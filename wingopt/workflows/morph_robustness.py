"""Robustness of the morphing controllers on plants that are not their model (issue 34, step 4).

A study samples mismatched plates (:class:`PlantCase`: moduli, d33, damping factors, patch
hysteresis and creep, sensor bias and noise), runs every shape with every controller on each
(:data:`CONTROLLERS`: the offset-free QP, today's QP, the LQR saturated at the limits), and records
per run the final shape error, the plant's best within the limits (its static optimum, with the
steady acting range of hysteresis and creep) and the excess. :func:`plant_record` is one task
(one plant: three shapes x three controllers, sharing the plant's exact ZOH); the Dask sweep
(``wingopt sweep`` with ``kind = "morph"``, :mod:`wingopt.workflows.sweep`) distributes and resumes
them; :func:`excess_table` summarises the records per shape and controller.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from wingopt.errors import InputError
from wingopt.plate import PlateModel
from wingopt.plate.shapes import SHAPES
from wingopt.workflows.morph import morph
from wingopt.workflows.morph_plant import HysteresisSettings, build_plant_model

__all__ = ["CONTROLLERS", "PlantCase", "sample_plants", "plant_record", "excess_table", "ISSUE_PLANTS"]

CONTROLLERS = {
    "qp": {"method": "qp"},
    "qp-today": {"method": "qp", "offset_free": False},
    "lqr-sat": {"method": "lqr"},
}
"""Controllers of a study: the offset-free QP (default), the QP without it, the LQR saturated at the limits."""


@dataclass(frozen=True)
class PlantCase:
    """One mismatched plant: factors on the model's problem, patch behaviour, sensor errors.

    ``sensor_bias`` is relative to each sensor's response to 1 kV on its own patch (signed);
    ``sensor_noise`` is the noise std in sensor units (m).
    """

    name: str
    scales: dict = field(default_factory=dict)
    hysteresis: float = 0.0
    creep: float = 0.0
    sensor_bias: float = 0.0
    sensor_noise: float = 0.0
    seed: int = 0

    def params(self) -> dict:
        """Flat parameters for a record (``scale.<name>`` for each factor)."""
        out = {"plant": self.name, **{f"scale.{k}": v for k, v in self.scales.items()}}
        out.update(hysteresis=self.hysteresis, creep=self.creep, sensor_bias=self.sensor_bias)
        out.update(sensor_noise=self.sensor_noise, seed=self.seed)
        return out


SETTLED_WINDOW = 0.25
"""Seconds at the end of a run whose mean shape is the *settled* shape (a lightly damped plate
still vibrates by +-1-3 % of the camber error at 2 s under any of the controllers)."""

ISSUE_PLANTS = (
    PlantCase("nominal"),
    PlantCase("E x1.1, d33 x0.8", {"moduli": 1.1, "d33": 0.8}),
    PlantCase("E x0.9, d33 x1.2", {"moduli": 0.9, "d33": 1.2}),
)
"""The plants of issue 34's table."""


def _range(spec: dict, key: str, default):
    v = spec.get(key, default)
    lo, hi = (v, v) if isinstance(v, (int, float)) and not isinstance(v, bool) else tuple(v)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise InputError(f"plants.{key} = {v!r}: expected a number or a range [low, high]")
    return float(lo), float(hi)


def sample_plants(count: int, seed: int = 0, ranges: dict | None = None) -> list[PlantCase]:
    """``count`` random plants: factors uniform in their ranges (damping log-uniform).

    Defaults (issue 34): moduli 0.9-1.1, d33 0.8-1.2, damping 0.5-2, hysteresis 0.15, no creep,
    no sensor bias or noise. ``ranges`` maps those names (and ``creep``, ``sensor_bias``,
    ``sensor_noise``) to a number or ``[low, high]``.
    """
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise InputError(f"plants.count = {count!r}: expected a positive whole number")
    ranges = dict(ranges or {})
    unknown = sorted(set(ranges) - {"moduli", "d33", "damping", "hysteresis", "creep", "sensor_bias", "sensor_noise"})
    if unknown:
        raise InputError(f"plants.{unknown[0]}: expected moduli, d33, damping, hysteresis, creep, sensor_bias, noise")
    r = {
        "moduli": _range(ranges, "moduli", [0.9, 1.1]),
        "d33": _range(ranges, "d33", [0.8, 1.2]),
        "damping": _range(ranges, "damping", [0.5, 2.0]),
        "hysteresis": _range(ranges, "hysteresis", 0.15),
        "creep": _range(ranges, "creep", 0.0),
        "sensor_bias": _range(ranges, "sensor_bias", 0.0),
        "sensor_noise": _range(ranges, "sensor_noise", 0.0),
    }
    if r["damping"][0] <= 0 or r["moduli"][0] <= 0 or r["d33"][0] <= 0:
        raise InputError("plants: moduli, d33 and damping factors must be positive")
    rng = np.random.default_rng(seed)
    out = []
    for i in range(count):
        u = rng.uniform(size=7)

        def lin(k, j, u=u):
            return r[k][0] + u[j] * (r[k][1] - r[k][0])

        damping = math.exp(math.log(r["damping"][0]) + u[2] * (math.log(r["damping"][1]) - math.log(r["damping"][0])))
        scales = {"moduli": round(lin("moduli", 0), 6), "d33": round(lin("d33", 1), 6), "damping": round(damping, 6)}
        out.append(
            PlantCase(
                f"random {i}",
                scales,
                hysteresis=round(lin("hysteresis", 3), 6),
                creep=round(lin("creep", 4), 6),
                sensor_bias=round(lin("sensor_bias", 5) * (1 if u[6] < 0.5 else -1), 6),
                sensor_noise=lin("sensor_noise", 6),
                seed=i,
            )
        )
    return out


def _bias(model: PlateModel, relative: float) -> np.ndarray | None:
    """A sensor offset of ``relative`` x each sensor's response to 1 kV on its own patch."""
    if relative == 0:
        return None
    own = np.abs(np.diag(model.sensing @ model.system.static_fields())) * 1000.0
    return relative * own


def plant_record(model: PlateModel, case: PlantCase, shapes=SHAPES, controllers=tuple(CONTROLLERS), t_end=2.0) -> dict:
    """One plant: every shape with every controller; the study's record (JSON-able).

    ``results[shape][controller]`` holds ``error``, ``best``, ``excess``, ``relative_excess``
    (excess over best), ``vmin_V``/``vmax_V`` (applied extremes) and ``within_limits``.
    """
    t0 = time.perf_counter()
    problem = model.problem
    plant = build_plant_model(problem, None, case.scales) if case.scales else None
    act = HysteresisSettings(width=case.hysteresis, creep=case.creep) if case.hysteresis or case.creep else None
    bias = _bias(plant or model, case.sensor_bias)
    lo, hi = problem.actuators.vmin, problem.actuators.vmax
    results: dict = {}
    for shape in shapes:
        results[shape] = {}
        for name in controllers:
            opts = dict(CONTROLLERS[name])
            method = opts.pop("method")
            run = morph(
                problem,
                shape,
                method,
                model=model,
                plant_model=plant,
                actuator=act,
                sensor_bias=bias,
                sensor_noise=case.sensor_noise,
                seed=case.seed,
                t_end=t_end,
                vmin=lo,
                vmax=hi,
                **opts,
            )
            s = run.summary()
            best = s["plant_static_optimum_error"]
            cl = run.closed_loop
            u = cl.u
            # The shape held, with the plate's residual vibration averaged out (last 0.25 s).
            tail = max(1, int(round(SETTLED_WINDOW / cl.plant_dt)))
            truth = plant or model
            settled = float(truth.m_norm(cl.z[-tail:].mean(axis=0) - run.target) / truth.m_norm(run.target))
            results[shape][name] = {
                "error": s["shape_error"],
                "best": best,
                "excess": s["excess_error"],
                "relative_excess": s["excess_error"] / best if best > 0 else float("nan"),
                "settled_error": settled,
                "settled_relative_excess": settled / best - 1.0 if best > 0 else float("nan"),
                "vmin_V": float(u.min()),
                "vmax_V": float(u.max()),
                "within_limits": bool(u.min() >= lo - 1e-9 and u.max() <= hi + 1e-9),
                "step_p99_s": float(np.percentile(run.closed_loop.step_seconds, 99)),
            }
    return {"params": case.params(), "case": asdict(case), "results": results, "duration_s": time.perf_counter() - t0}


def excess_table(records: list[dict], tolerance: float = 0.02, metric: str = "relative_excess") -> list[dict]:
    """Per shape and controller: median, p90 and max of ``metric`` over the records, share within ``tolerance``.

    ``metric``: ``"relative_excess"`` (final shape error) or ``"settled_relative_excess"`` (the
    mean shape of the last :data:`SETTLED_WINDOW` s).
    """
    rows = []
    shapes = list(dict.fromkeys(s for r in records for s in r.get("results", {})))
    ctrls = list(dict.fromkeys(c for r in records for s in r.get("results", {}).values() for c in s))
    for shape in shapes:
        for c in ctrls:
            rel = np.array([r["results"][shape][c][metric] for r in records if c in r["results"].get(shape, {})])
            lim = [r["results"][shape][c]["within_limits"] for r in records if c in r["results"].get(shape, {})]
            if rel.size == 0:
                continue
            rows.append(
                {
                    "shape": shape,
                    "controller": c,
                    "metric": metric,
                    "plants": int(rel.size),
                    "median": float(np.median(rel)),
                    "p90": float(np.percentile(rel, 90)),
                    "max": float(rel.max()),
                    f"within_{tolerance:g}": float(np.mean(rel <= tolerance)),
                    "within_limits": float(np.mean(lim)),
                }
            )
    return rows
