"""Value types validated once, at the boundary: voltage limits, noise level, lambda choice.

The command line, the problem files and the top-level API turn what the user gave into these
types; the engines below take them and do not validate again. Each type states its unit and its
"no value" explicitly (an unlimited voltage side is ``-inf``/``+inf``, never ``None`` or ``1e9``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError

__all__ = ["VoltageLimits", "NoiseLevel", "LambdaChoice"]


def _number(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} = {value!r}: expected a number") from None
    return v


@dataclass(frozen=True, eq=False)
class VoltageLimits:
    """Per-patch voltage limits (V): ``lower[i] < upper[i]``, ``-inf``/``+inf`` on an unlimited side.

    Build with :meth:`from_user` (scalars or one value per patch, ``None`` = unlimited on that
    side) or :meth:`unlimited`.
    """

    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def unlimited(cls, patches: int) -> VoltageLimits:
        """No limit on either side (the seed's LQR)."""
        return cls(np.full(patches, -np.inf), np.full(patches, np.inf))

    @classmethod
    def from_user(cls, vmin, vmax, patches: int) -> VoltageLimits:
        """Validate ``vmin``/``vmax`` (V; ``None``: unlimited on that side; scalar or one per patch)."""
        if int(patches) < 1:
            raise InputError(f"patches = {patches!r}: the plate has no piezo patches to drive")
        sides = []
        for name, v, inf in (("vmin", vmin, -np.inf), ("vmax", vmax, np.inf)):
            if v is None:
                sides.append(np.full(patches, inf))
                continue
            arr = np.atleast_1d(np.asarray(v, dtype=float)) if not isinstance(v, str) else None
            if arr is None or arr.ndim != 1 or arr.size not in (1, patches):
                raise InputError(f"{name} = {v!r}: expected one voltage or one per patch ({patches})")
            if not np.all(np.isfinite(arr)):
                raise InputError(f"{name} = {v!r}: expected finite voltages (V); leave it out for no limit")
            sides.append(np.broadcast_to(arr, (patches,)).astype(float))
        lo, hi = sides
        if np.any(lo >= hi):
            raise InputError(f"vmin = {vmin!r}, vmax = {vmax!r}: expected vmin < vmax")
        return cls(lo, hi)

    @property
    def patches(self) -> int:
        return self.lower.size

    @property
    def is_unlimited(self) -> bool:
        return bool(np.all(np.isinf(self.lower)) and np.all(np.isinf(self.upper)))

    def side(self, which: str) -> np.ndarray | None:
        """``"lower"``/``"upper"`` as an array, or ``None`` where that side is unlimited on every patch."""
        arr = self.lower if which == "lower" else self.upper
        return None if np.all(np.isinf(arr)) else arr.copy()

    def scalar(self, which: str) -> float | None:
        """The side as one number when it is the same on every patch (``None``: unlimited)."""
        arr = self.side(which)
        if arr is None:
            return None
        if np.ptp(arr) != 0:
            raise InputError(f"{which} voltage limits differ per patch: no single value")
        return float(arr[0])

    def clip(self, u: np.ndarray) -> np.ndarray:
        """``u`` saturated at the limits."""
        return np.clip(u, self.lower, self.upper)


@dataclass(frozen=True)
class NoiseLevel:
    """Simulated sensor noise as a fraction of each sensor's peak output (0.01 = 1 %)."""

    fraction: float

    def __post_init__(self) -> None:
        f = _number("noise", self.fraction)
        if not (math.isfinite(f) and 0.0 <= f <= 1.0):
            raise InputError(
                f"noise = {self.fraction!r}: expected a fraction of the sensors' peak in [0, 1] (0.01 = 1 %)"
            )
        object.__setattr__(self, "fraction", f)

    @classmethod
    def from_percent(cls, percent: float) -> NoiseLevel:
        p = _number("noise", percent)
        if not (math.isfinite(p) and 0.0 <= p <= 100.0):
            raise InputError(f"noise = {percent!r}: expected a percentage between 0 and 100")
        return cls(p / 100.0)

    @property
    def percent(self) -> float:
        return 100.0 * self.fraction


@dataclass(frozen=True)
class LambdaChoice:
    """How an estimator's Tikhonov weight is set: a fixed value, or a data-only rule by name.

    ``rule`` names a rule of :mod:`wingopt.estimation.core.lambda_rules` (resolved per estimator there);
    ``None`` means the estimator's default rule.
    """

    value: float | None = None
    rule: str | None = None

    def __post_init__(self) -> None:
        if self.value is not None:
            v = _number("lambda", self.value)
            if not (math.isfinite(v) and 1e-30 <= v <= 1e30):
                raise InputError(
                    f"lambda = {self.value!r}: expected a positive regularization weight from 1e-30 to 1e30"
                )
            object.__setattr__(self, "value", v)
            if self.rule is not None:
                raise InputError("lambda: give a fixed value or a rule, not both")

    @classmethod
    def fixed(cls, value: float) -> LambdaChoice:
        return cls(value=value)

    @property
    def is_fixed(self) -> bool:
        return self.value is not None
