"""Small argument checks shared by the workflows (morph, identify) and the command line."""

from __future__ import annotations

import numpy as np

from wingopt.errors import InputError

__all__ = ["check_seed"]


def check_seed(seed) -> int:
    """A noise seed: a whole number in ``[0, 2**32)`` (numpy's range); bools and floats refused."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= int(seed) < 2**32:
        raise InputError(f"seed = {seed!r}: expected a whole number from 0 to 4294967295")
    return int(seed)
