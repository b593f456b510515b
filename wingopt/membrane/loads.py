"""Pressure loads, load histories and initial shapes of the identification protocols.

The seed's load cases (spec §2, eqs. 6.47–6.49) and the leading-edge case ``LE`` by name
(:func:`load_case`); the wind tunnel's pressures that act up to the frame (:func:`tunnel_load`,
spec §10); load factors over time, a 1-cos :class:`Gust` and stationary :class:`Buffeting`; the
protocol's bubble.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from wingopt.errors import InputError

__all__ = [
    "PressureLoad",
    "load_case",
    "LOAD_CASES",
    "TUNNEL_LOADS",
    "bubble",
    "push",
    "leading_edge_load",
    "tunnel_load",
    "Gust",
    "Buffeting",
]

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
    if name in TUNNEL_LOADS:
        return tunnel_load(name, W, L)
    raise InputError(f"load = {name!r}: expected one of {', '.join(LOAD_CASES + TUNNEL_LOADS)}")


def bubble(width: float, height: float, peak: float = 0.01) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """Initial shape ``peak * 16 xi (1 - xi) eta (1 - eta)`` (1 cm peak by default)."""

    def shape(x, y):
        xi, eta = np.asarray(x) / width, np.asarray(y) / height
        return peak * 16.0 * xi * (1 - xi) * eta * (1 - eta)

    return shape


def push(width: float, height: float, peak: float = 0.004) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """An off-centre push, zero on the frame: a calibration record's release shape (the tunnel stand-in's)."""

    def shape(x, y):
        xi, eta = np.asarray(x) / width, np.asarray(y) / height
        return peak * 6.75 * xi**2 * (1 - xi) * 16 * eta * (1 - eta) * (0.6 + 0.4 * eta)

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


TUNNEL_LOADS = ("tunnel-LE", "tunnel-TE", "tunnel-bump", "tunnel-anti")
"""The wind tunnel's steady pressures (:func:`tunnel_load`): they act up to the frame."""

_ALPHA, _CAMBER, _REG = np.deg2rad(4.0), 0.043, 0.05


def _chord_le(xi):
    """Thin-airfoil load of a cambered plate at 4 deg (per dynamic pressure), LE singularity regularised."""
    flat = 4 * _ALPHA * np.sqrt((1 - xi + _REG) / (xi + _REG))
    return flat + 32 * _CAMBER * np.sqrt(np.clip(xi * (1 - xi), 0.0, None))


def _span(eta):
    return 0.6 + 0.4 * np.sin(np.pi * eta)


def _mean(shape) -> float:
    g = (np.arange(400) + 0.5) / 400
    X, E = np.meshgrid(g, g, indexing="ij")
    return float(np.mean(shape(X, E)))


def tunnel_load(name: str, width: float, height: float, mean: float = 180.0) -> PressureLoad:
    """A steady wind-tunnel pressure that acts up to the frame (spec §10), by name.

    ``tunnel-LE``: the thin-airfoil load of a cambered plate (4 deg, camber 6 mm on 140 mm; the
    leading-edge singularity regularised) ``4 a sqrt((1 - xi + d)/(xi + d)) + 32 (h/c) sqrt(xi (1 - xi))``
    times ``0.6 + 0.4 sin(pi eta)`` spanwise (0.6 on the frame at ``y = 0, L``), leading edge at
    ``x = 0``; ``tunnel-TE`` the same mirrored in x; ``tunnel-bump`` an off-centre Gaussian
    (``x = 0.3 W, y = 0.65 L``, sigma ``0.15 W x 0.2 L``); scaled to a ``mean`` pressure (Pa);
    ``tunnel-anti`` ``(LE(x) - LE(W - x)) / 2`` of the LE load at that mean: zero net lift.
    """
    W, L = width, height

    def le(xi, eta):
        return _chord_le(xi) * _span(eta)

    shapes = {
        "tunnel-LE": le,
        "tunnel-TE": lambda xi, eta: le(1 - xi, eta),
        "tunnel-bump": lambda xi, eta: np.exp(-0.5 * (((xi - 0.3) / 0.15) ** 2 + ((eta - 0.65) / 0.2) ** 2)),
    }
    if name == "tunnel-anti":
        s0 = mean / _mean(le)
        return PressureLoad(
            name, lambda x, y: 0.5 * s0 * (le(x / W, y / L) - le(1 - x / W, y / L)), "(LE(x) - LE(W - x)) / 2"
        )
    if name not in shapes:
        raise InputError(f"tunnel load = {name!r}: expected one of {', '.join(TUNNEL_LOADS)}")
    shape = shapes[name]
    scale = mean / _mean(shape)
    return PressureLoad(name, lambda x, y: scale * shape(x / W, y / L), f"{name}, mean {mean:g} Pa")


@dataclass(frozen=True)
class Buffeting:
    """A stationary Gaussian load factor ``1 + eps(t)``: the flow's buffeting on a wind-tunnel wing.

    ``eps`` is white noise through ``order`` cascaded first-order low-passes of corner
    ``corner_hz`` (one-sided PSD ``∝ (1 + (f/fc)^2)^-order``: most of its energy below the corner,
    a turbulence-like roll-off above), scaled to ``rms``, drawn from ``seed``. It is generated by
    the filters' exact discretisation on a grid of ``step`` s (fine against the membrane's modes)
    from the stationary state, over ``duration`` s, and is linear between grid points.
    """

    rms: float = 0.03
    corner_hz: float = 30.0
    order: int = 2
    seed: int = 0
    duration: float = 5.0
    step: float = 1.0 / 2400.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.rms) and 0 <= self.rms < 1):
            raise InputError(f"buffeting rms = {self.rms!r}: expected a fraction of the load in [0, 1)")
        if not (np.isfinite(self.corner_hz) and self.corner_hz > 0):
            raise InputError(f"buffeting corner = {self.corner_hz!r}: expected a positive frequency (Hz)")
        if self.order not in (1, 2, 3):
            raise InputError(f"buffeting order = {self.order!r}: expected 1, 2 or 3")

    @functools.cached_property
    def _series(self) -> tuple[np.ndarray, np.ndarray]:
        n = int(np.ceil(self.duration / self.step)) + 2
        t = np.arange(n) * self.step
        if self.rms == 0:
            return t, np.zeros(n)
        a, k = 2 * np.pi * self.corner_hz, self.order
        A = -a * np.eye(k) + np.diag(np.full(k - 1, a), -1)
        B = np.zeros((k, 1))
        B[0, 0] = a
        big = np.zeros((2 * k, 2 * k))  # Van Loan: transition and process noise of unit white noise
        big[:k, :k], big[:k, k:], big[k:, k:] = -A, B @ B.T, A.T
        E = sla.expm(big * self.step)
        F = E[k:, k:].T
        Q = F @ E[:k, k:]
        Q = 0.5 * (Q + Q.T) + 1e-300 * np.eye(k)
        P = sla.solve_continuous_lyapunov(A, -B @ B.T)
        rng = np.random.default_rng(self.seed)
        x = np.linalg.cholesky(P) @ rng.standard_normal(k)
        W = rng.standard_normal((n, k)) @ np.linalg.cholesky(Q).T
        out = np.empty(n)
        for i in range(n):
            out[i] = x[-1]
            x = F @ x + W[i]
        return t, out * (self.rms / np.sqrt(P[-1, -1]))

    def factor(self, t):
        """``1 + eps(t)`` at times ``t`` (s); beyond ``duration`` an error."""
        t = np.asarray(t, dtype=float)
        grid, eps = self._series
        if np.any(t > grid[-1]) or np.any(t < 0):
            raise InputError(f"buffeting: t up to {float(np.max(t)):g} s, generated for {self.duration:g} s")
        return 1.0 + np.interp(t, grid, eps)
