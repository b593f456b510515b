"""A plant that is not the model: the plate a morph run simulates, built from another problem.

``wingopt morph --plant PLANT.toml`` (a problem file for the simulated plate: its own moduli,
thicknesses, d33, damping) or ``--plant-scale e1=1.1,d33=0.8,damping=2`` (the model's problem
with parameters scaled) give the closed-loop harness a plant whose operators differ from the
controller's model (:func:`wingopt.control.closed_loop.simulate_closed_loop`'s ``plant_model``).
The plant must have the model's geometry, patches and mesh, so that their fields and voltages
mean the same thing; :func:`plant_problem` checks it.

Scale names (:data:`PLANT_SCALES`), each a factor > 0:

* ``moduli``: every in-plane modulus (E1, E2, G12) of every material (skin, battens, patches: a
  uniformly stiffer laminate; with ``d33`` this is issue 34's "E" column, whose static optima it
  reproduces to four digits); ``skin``, ``batten``: the moduli of that material alone;
  ``e1``, ``e2``, ``g12``: that modulus alone, of the skin and the battens (the structure);
* ``d33``: the patches' piezoelectric coefficient (their moment per volt);
* ``damping``: every Kelvin-Voigt and viscous coefficient (skin, battens, patches);
* ``density``: every density (skin, battens, patches).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from wingopt.control.hysteresis import HysteresisSettings, PatchActuator
from wingopt.control.static_optimum import static_optimum
from wingopt.errors import InputError
from wingopt.plate import PlateModel
from wingopt.problem import load_problem

__all__ = [
    "PLANT_SCALES",
    "parse_plant_scale",
    "scaled_problem",
    "plant_problem",
    "describe_plant",
    "build_plant_model",
    "plant_extras",
    "build_actuator",
    "HysteresisSettings",
]

PLANT_SCALES = ("moduli", "skin", "batten", "e1", "e2", "g12", "d33", "damping", "density")
"""Names ``--plant-scale`` accepts (see the module docstring)."""

# name -> (materials it scales, moduli it scales)
_MODULI = {
    "moduli": (("skin", "batten", "piezo"), ("e1", "e2", "g12")),
    "skin": (("skin",), ("e1", "e2", "g12")),
    "batten": (("batten",), ("e1", "e2", "g12")),
    "e1": (("skin", "batten"), ("e1",)),
    "e2": (("skin", "batten"), ("e2",)),
    "g12": (("skin", "batten"), ("g12",)),
}


def parse_plant_scale(text) -> dict[str, float]:
    """``"e1=1.1,d33=0.8"`` (or a mapping) -> ``{"e1": 1.1, "d33": 0.8}``, each name and factor checked."""
    if text is None:
        return {}
    if isinstance(text, dict):
        items = list(text.items())
    else:
        items = []
        for part in str(text).split(","):
            if not part.strip():
                continue
            name, sep, value = part.partition("=")
            if not sep:
                raise InputError(f"plant-scale = {text!r}: expected NAME=FACTOR pairs separated by commas")
            try:
                items.append((name.strip(), float(value)))
            except ValueError:
                raise InputError(f"plant-scale {name.strip()} = {value.strip()!r}: expected a number") from None
    out: dict[str, float] = {}
    for name, value in items:
        if name not in PLANT_SCALES:
            raise InputError(f"plant-scale name {name!r}: expected one of {', '.join(PLANT_SCALES)}")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
            raise InputError(f"plant-scale {name} = {value!r}: expected a positive finite factor")
        if name in out:
            raise InputError(f"plant-scale {name}: given twice")
        out[name] = float(value)
    return out


def _material(mat, scales: dict, which: str):
    changes = {}
    for name, (materials, fields) in _MODULI.items():
        if name in scales and which in materials:
            for f in fields:  # factors of several names multiply
                changes[f] = changes.get(f, getattr(mat, f)) * scales[name]
    if "damping" in scales:
        k = scales["damping"]
        changes["kelvin_voigt"] = tuple(v * k for v in mat.kelvin_voigt)
        changes["viscous"] = mat.viscous * k
    if "density" in scales:
        changes["density"] = mat.density * scales["density"]
    return dataclasses.replace(mat, **changes) if changes else mat


def scaled_problem(problem, scales: dict[str, float]):
    """``problem`` with the parameters of ``scales`` multiplied (names of :data:`PLANT_SCALES`)."""
    scales = parse_plant_scale(scales)
    if not scales:
        return problem
    skin = dataclasses.replace(problem.skin, material=_material(problem.skin.material, scales, "skin"))
    batten = dataclasses.replace(problem.batten, material=_material(problem.batten.material, scales, "batten"))
    piezo = problem.piezo
    if piezo is not None:
        piezo = dataclasses.replace(
            piezo,
            material=_material(piezo.material, scales, "piezo"),
            d33=piezo.d33 * scales.get("d33", 1.0),
        )
    label = ",".join(f"{k}={v:g}" for k, v in scales.items())
    return dataclasses.replace(problem, skin=skin, batten=batten, piezo=piezo, name=f"{problem.name} [{label}]")


def plant_problem(model_problem, plant=None, plant_scale=None):
    """The plant's problem: ``plant`` (a problem, file or built-in name; default the model's), scaled.

    Returns ``None`` when neither is given (the plant is the model). The plant must have the
    model's geometry, patches (names and rectangles) and mesh: an :class:`InputError` names the
    first difference.
    """
    scales = parse_plant_scale(plant_scale)
    if plant is None and not scales:
        return None
    base = model_problem if plant is None else (load_problem(plant) if isinstance(plant, (str, Path)) else plant)
    if getattr(base, "kind", None) != "plate":
        raise InputError(f"plant = {plant!r}: expected a plate problem, got kind {getattr(base, 'kind', None)!r}")
    base = base.with_mesh(model_problem.nodes) if base.nodes != model_problem.nodes else base
    for name in ("width", "length"):
        if not math.isclose(getattr(base, name), getattr(model_problem, name), rel_tol=1e-12):
            raise InputError(
                f"plant {name} = {getattr(base, name)!r}: expected the model's {getattr(model_problem, name)!r} "
                "(plant and model must share the geometry)"
            )
    if [(p.name, p.rect) for p in base.patches] != [(p.name, p.rect) for p in model_problem.patches]:
        raise InputError(f"plant patches {list(base.patch_names)}: expected the model's patches and rectangles")
    return scaled_problem(base, scales)


def describe_plant(model_problem, plant_prob) -> dict:
    """Names of model and plant for a summary (``plant_problem`` ``None``: the model itself)."""
    if plant_prob is None:
        return {"model": model_problem.name, "plant": "model"}
    return {"model": model_problem.name, "plant": plant_prob.name, "plant_source": getattr(plant_prob, "source", None)}


def build_plant_model(model_problem, plant=None, plant_scale=None, nodes=None):
    """The plate model of the plant (``None`` when the plant is the controller's model)."""
    prob = plant_problem(model_problem if nodes is None else model_problem.with_mesh(nodes), plant, plant_scale)
    return None if prob is None else PlateModel.from_problem(prob)


def plant_extras(model, plant_model, target, limits, closed_loop, actuator=None, sensor_bias=None) -> dict:
    """Summary entries of the plant: its names, its best holdable shape within ``limits``, the excess.

    ``plant_static_optimum_error`` is :func:`~wingopt.control.static_optimum.static_optimum` on the
    plant (the best equilibrium the plant can hold within the limits, the QP's default input
    weight; with hysteresis and creep, within the steady acting voltages the limits allow, see
    :meth:`~wingopt.control.hysteresis.PatchActuator.steady_range`); ``excess_error`` is the run's
    final shape error minus it (> 0: above the floor).
    """
    truth = model if plant_model is None else plant_model
    lo, hi = limits.side("lower"), limits.side("upper")
    if actuator is not None and hasattr(actuator, "steady_range") and lo is not None and hi is not None:
        # Hysteresis and creep change what the patches can hold at the limits: the best is within those.
        lo, hi = (np.asarray(v, dtype=float) for v in np.vectorize(actuator.steady_range)(lo, hi))
    best = static_optimum(truth, target, vmin=lo, vmax=hi)
    out = describe_plant(model.problem, None if plant_model is None else plant_model.problem)
    out.update(
        plant_static_optimum_error=float(best.shape_error),
        plant_static_optimum_voltages_V=[float(v) for v in best.voltages],
        excess_error=float(closed_loop.final_shape_error - best.shape_error),
    )
    if actuator is not None:
        settings = getattr(actuator, "settings", None)
        out["plant_actuator"] = dataclasses.asdict(settings) if settings is not None else type(actuator).__name__
    if sensor_bias is not None:
        out["sensor_bias"] = np.broadcast_to(np.asarray(sensor_bias, dtype=float), (model.n_inputs,)).tolist()
    return out


def build_actuator(spec, problem, m: int):
    """The plant's patch behaviour: ``None``, a width (float), :class:`HysteresisSettings` or an actuator.

    ``None``: the plant problem's own (``[actuators]`` ``hysteresis``, ``creep``, ``creep_time``;
    none by default). The play thresholds span the problem's ``[actuators]`` range (the patches'
    own, whatever the controller's limits).
    """
    if spec is None:
        act = getattr(problem, "actuators", None)
        width, creep = getattr(act, "hysteresis", 0.0), getattr(act, "creep", 0.0)
        if not (width or creep):
            return None
        spec = HysteresisSettings(width=width, creep=creep, creep_time=act.creep_time)
    if hasattr(spec, "apply"):
        return spec
    if isinstance(spec, bool) or not isinstance(spec, (int, float, HysteresisSettings)):
        raise InputError(f"actuator = {spec!r}: expected a hysteresis width, HysteresisSettings or an actuator")
    settings = spec if isinstance(spec, HysteresisSettings) else HysteresisSettings(width=float(spec))
    if not settings.active:
        return None
    act = problem.actuators
    return PatchActuator(settings, act.vmin, act.vmax, m)
