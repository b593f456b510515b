"""Morphing target shapes of Table 5.1 (``a`` in m; the root ``y = L`` is clamped)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wingopt.errors import InputError
from wingopt.problem.plate import SHAPES

__all__ = ["target_function", "SHAPES"]


def target_function(
    shape: str, width: float, length: float, a: float
) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """The desired deflection ``z_d(x, y)`` of a Table 5.1 shape.

    * ``twist``:   ``(a/L)(1 - 2x/W)(L - y)`` — tip corners at ``+a`` (x = 0) and ``-a`` (x = W);
    * ``camber``:  ``(2a/(W^2 L)) x (W - x)(L - y)`` — tip mid-chord raised by ``a/2``, edges at 0;
    * ``bending``: ``-(a/L^2)(y - L)^2`` — tip ``-a``, zero value and slope at the root.
    """
    W, L = float(width), float(length)
    if shape == "twist":
        return lambda x, y: (a / L) * (1.0 - 2.0 * x / W) * (L - y)
    if shape == "camber":
        return lambda x, y: (2.0 * a / (W * W * L)) * x * (W - x) * (L - y)
    if shape == "bending":
        return lambda x, y: -(a / (L * L)) * (y - L) ** 2 + 0.0 * x
    raise InputError(f"shape = {shape!r}: expected one of {', '.join(SHAPES)}")
