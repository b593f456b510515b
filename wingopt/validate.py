"""Small argument checks shared by the workflows (morph, identify) and the command line."""

from __future__ import annotations

import numpy as np

from wingopt.errors import InputError

__all__ = ["check_seed", "check_nodes", "check_number"]


def check_seed(seed) -> int:
    """A noise seed: a whole number in ``[0, 2**32)`` (numpy's range); bools and floats refused."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= int(seed) < 2**32:
        raise InputError(f"seed = {seed!r}: expected a whole number from 0 to 4294967295")
    return int(seed)


def check_nodes(nodes, name: str = "nodes") -> tuple[int, int]:
    """A mesh ``(nx, ny)``: two whole numbers, at least 4 each (``"13x7"`` text goes through
    :func:`wingopt.problem.parse_mesh`)."""
    if isinstance(nodes, (str, bytes)):
        raise InputError(
            f"{name} = {nodes!r}: expected (nx, ny) nodes in x and y, e.g. (25, 13); parse text such "
            "as '25x13' with wingopt.parse_mesh"
        )
    try:
        items = list(nodes)
    except TypeError:
        raise InputError(f"{name} = {nodes!r}: expected (nx, ny) nodes in x and y, e.g. (25, 13)") from None
    if len(items) != 2:
        raise InputError(f"{name} = {nodes!r}: expected two numbers of nodes (nx, ny) (the mesh), got {len(items)}")
    out = []
    for v in items:
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or int(v) < 4:
            raise InputError(f"{name} = {nodes!r}: expected whole numbers of nodes (the mesh), at least 4 each")
        out.append(int(v))
    return out[0], out[1]


def check_number(
    name: str,
    value,
    *,
    lo: float | None = None,
    hi: float | None = None,
    positive: bool = False,
    allow_none: bool = False,
) -> float | None:
    """A finite real number (``positive``: > 0; ``lo`` <= value <= ``hi``); an :class:`InputError` naming ``name``."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(f"{name} = {value!r}: expected a number")
    v = float(value)
    if not np.isfinite(v):
        raise InputError(f"{name} = {value!r}: expected a finite number")
    if positive and not v > 0:
        raise InputError(f"{name} = {value!r}: expected a positive number")
    if lo is not None and v < lo:
        raise InputError(f"{name} = {value!r}: expected at least {lo:g}")
    if hi is not None and v > hi:
        raise InputError(f"{name} = {value!r}: expected at most {hi:g}")
    return v
