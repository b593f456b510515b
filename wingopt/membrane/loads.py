"""Pressure loads, load histories and initial shapes of the identification protocols.

The seed's load cases (spec §2, eqs. 6.47–6.49) and the leading-edge case ``LE`` by name
(:func:`load_case`); a 1-cos :class:`Gust` as a load factor over time; the protocol's bubble.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from wingopt.errors import InputError

__all__ = ["PressureLoad", "load_case", "LOAD_CASES", "bubble", "leading_edge_load", "Gust"]

LOAD_CASES = ("L1", "L2", "L3", "consistency", "LE")
"""Load cases by name: the seed's L1–L3 and consistency rectangle, and the leading-edge case LE."""


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
    if name == "LE":
        return leading_edge_load(W, L, A)
    raise InputError(f"load = {name!r}: expected one of {', '.join(LOAD_CASES)}")


def bubble(width: float, height: float, peak: float = 0.01) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """Initial shape ``peak * 16 xi (1 - xi) eta (1 - eta)`` (1 cm peak by default)."""

    def shape(x, y):
        xi, eta = np.asarray(x) / width, np.asarray(y) / height
        return peak * 16.0 * xi * (1 - xi) * eta * (1 - eta)

    return shape


def leading_edge_load(width: float, height: float, amplitude: float = 200.0) -> PressureLoad:
    """One-sign load peaking at a quarter chord: ``A (256/27) xi (1 - xi)^3 sin(pi eta)``.

    Its maximum ``A`` is at ``xi = 1/4``; it vanishes on the frame (like L1) and its lift is
    ``A (256/27)(1/20)(2/pi) W L`` (0.591 N for the default wing and 200 Pa).
    """
    W, L, A = width, height, amplitude
    scale = A * 256.0 / 27.0

    def pressure(x, y):
        xi = x / W
        return scale * xi * (1 - xi) ** 3 * np.sin(np.pi * y / L)

    return PressureLoad("LE", pressure, f"{A:g} (256/27) xi (1-xi)^3 sin(pi eta), peak at xi = 1/4")


@dataclass(frozen=True)
class Gust:
    """Load factor ``1 + amplitude (1 - cos(2 pi (t - start)/duration))`` on ``[start, start + duration]``.

    The default (``wingopt identify --gust``) starts at 0.4 s, after the protocol bubble's transient,
    and peaks at +60 % of the steady load 0.1 s later.
    """

    start: float = 0.4
    duration: float = 0.2
    amplitude: float = 0.3

    def __post_init__(self) -> None:
        if not (np.isfinite(self.start) and self.start >= 0):
            raise InputError(f"gust start = {self.start!r}: expected a time >= 0 (s)")
        if not (np.isfinite(self.duration) and self.duration > 0):
            raise InputError(f"gust duration = {self.duration!r}: expected a positive duration (s)")
        if not np.isfinite(self.amplitude):
            raise InputError(f"gust amplitude = {self.amplitude!r}: expected a finite number")

    def factor(self, t):
        t = np.asarray(t, dtype=float)
        s = (t - self.start) / self.duration
        inside = (s >= 0) & (s <= 1)
        return np.where(inside, 1.0 + self.amplitude * (1.0 - np.cos(2 * np.pi * s)), 1.0)
