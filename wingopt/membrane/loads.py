"""Pressure loads and initial shapes of the identification protocol (spec §2, eqs. 6.47–6.49)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from wingopt.errors import InputError

__all__ = ["PressureLoad", "load_case", "LOAD_CASES", "bubble"]

LOAD_CASES = ("L1", "L2", "L3", "consistency")


@dataclass(frozen=True)
class PressureLoad:
    """A pressure field ``P(x, y)`` in Pa, with the lines where it jumps (for exact quadrature)."""

    name: str
    pressure: Callable[[np.ndarray, np.ndarray], np.ndarray]
    description: str = ""
    breaks_x: tuple[float, ...] = field(default=())
    breaks_y: tuple[float, ...] = field(default=())

    def __call__(self, x, y):
        return self.pressure(np.asarray(x, dtype=float), np.asarray(y, dtype=float))


def load_case(name: str, width: float, height: float, amplitude: float = 200.0) -> PressureLoad:
    """The seed's load cases on a ``width x height`` membrane.

    ``L1 = A sin(pi xi) sin(pi eta)``, ``L2 = A sin(2 pi xi) sin(pi eta)``,
    ``L3 = A sin(pi xi / 2) sin(pi eta)`` (largest along ``x = W``), with ``xi = x/W``,
    ``eta = y/L``; ``consistency`` is ``-A`` on a rectangle, 0 elsewhere.
    """
    W, L, A = width, height, amplitude
    if name == "L1":
        return PressureLoad(
            name, lambda x, y: A * np.sin(np.pi * x / W) * np.sin(np.pi * y / L), "200 sin(pi xi) sin(pi eta)"
        )
    if name == "L2":
        return PressureLoad(
            name, lambda x, y: A * np.sin(2 * np.pi * x / W) * np.sin(np.pi * y / L), "200 sin(2 pi xi) sin(pi eta)"
        )
    if name == "L3":
        return PressureLoad(
            name, lambda x, y: A * np.sin(0.5 * np.pi * x / W) * np.sin(np.pi * y / L), "200 sin(pi xi / 2) sin(pi eta)"
        )
    if name == "consistency":
        # The rectangle scales with the membrane (it is the middle half in x and in y).
        x0, x1 = 0.25 * W, 0.75 * W
        y0, y1 = 0.25 * L, 0.75 * L

        def rect(x, y):
            inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
            return np.where(inside, -A, 0.0)

        return PressureLoad(name, rect, f"-200 Pa on [{x0}, {x1}] x [{y0}, {y1}]", (x0, x1), (y0, y1))
    raise InputError(f"load = {name!r}: expected one of {', '.join(LOAD_CASES)}")


def bubble(width: float, height: float, peak: float = 0.01) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """Initial shape ``peak * 16 xi (1 - xi) eta (1 - eta)`` (1 cm peak by default)."""

    def shape(x, y):
        xi, eta = np.asarray(x) / width, np.asarray(y) / height
        return peak * 16.0 * xi * (1 - xi) * eta * (1 - eta)

    return shape
