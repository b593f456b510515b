"""The plate wing with piezocomposite patch pairs (chapters 4–5): layout, FE model, targets.

The laminate and piezo material laws are in :mod:`wingopt.materials` (below both this package and
:mod:`wingopt.problem`); they are re-exported here for convenience.
"""

from wingopt.materials import (
    isotropic_stiffness,
    laminate_rigidity,
    plate_rigidity,
    reduced_stiffness,
    rotate,
    symmetric_pair_rigidity,
)
from wingopt.plate.model import PlateModel, plate_space

__all__ = [
    "PlateModel",
    "plate_space",
    "reduced_stiffness",
    "isotropic_stiffness",
    "rotate",
    "laminate_rigidity",
    "plate_rigidity",
    "symmetric_pair_rigidity",
]
