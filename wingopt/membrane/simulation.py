"""Simulated membrane responses: exact ZOH in modal coordinates, full fields and sensor outputs."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError
from wingopt.membrane.loads import PressureLoad
from wingopt.membrane.model import MembraneModel

__all__ = ["Trajectory", "simulate_response", "load_history"]


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A simulated run: times ``(N+1,)``, deflection and velocity coefficients ``(N+1, n)``,
    load coefficients held on each step ``(N, n)`` and clean sensor outputs ``(N+1, p)``."""

    t: np.ndarray
    z: np.ndarray
    zdot: np.ndarray
    load: np.ndarray
    outputs: np.ndarray


def load_history(model: MembraneModel, load, steps: int, dt: float) -> np.ndarray:
    """Load coefficients ``(steps, n)`` held over each step.

    ``load`` may be a coefficient vector ``(n,)``, a history ``(steps, n)``, a pressure field
    (:class:`PressureLoad` or callable ``(x, y)``; projected once), or a callable ``t -> (n,)``.
    """
    n = model.n
    if isinstance(load, PressureLoad):
        return np.broadcast_to(model.project(load), (steps, n))
    if callable(load):
        try:
            first = np.asarray(load(0.0), dtype=float)
        except TypeError:
            first = None
        if first is not None and first.shape == (n,):
            return np.stack([load(k * dt) for k in range(steps)])
        return np.broadcast_to(model.project(load), (steps, n))
    arr = np.asarray(load, dtype=float)
    if arr.shape == (n,):
        return np.broadcast_to(arr, (steps, n))
    if arr.shape == (steps, n):
        return arr
    raise InputError(f"load: shape {arr.shape}, expected ({n},) or ({steps}, {n})")


def simulate_response(
    model: MembraneModel,
    load,
    t_end: float = 1.0,
    dt: float | None = None,
    z0: np.ndarray | Callable | None = None,
    v0: np.ndarray | None = None,
) -> Trajectory:
    """Response of the membrane from ``(z0, v0)`` (default rest) under ``load`` for ``t_end`` s.

    Exact zero-order hold of the full model, evaluated mode by mode (the damping is Rayleigh,
    so the modes decouple exactly).
    """
    dt = model.problem.identification.dt if dt is None else dt
    if not (np.isfinite(t_end) and t_end > 0):
        raise InputError(f"t_end = {t_end!r}: expected a positive duration (s)")
    steps = int(round(t_end / dt))
    if steps < 1:
        raise InputError(f"t_end = {t_end!r}: shorter than one sample (dt = {dt})")
    n = model.n
    z0 = np.zeros(n) if z0 is None else (model.project(z0) if callable(z0) else np.asarray(z0, float))
    v0 = np.zeros(n) if v0 is None else np.asarray(v0, float)
    forcing = load_history(model, load, steps, dt)
    modal = model.modal()
    disc = modal.discretize(dt)
    Q, Qd = disc.simulate(modal.to_modal(z0, model.mass), modal.to_modal(v0, model.mass), forcing)
    Z = Q @ modal.shapes.T
    Zd = Qd @ modal.shapes.T
    return Trajectory(np.arange(steps + 1) * dt, Z, Zd, np.asarray(forcing), model.sensors.outputs(Z))
