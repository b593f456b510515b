"""The plate wing with piezocomposite patch pairs (chapters 4–5): laminate, layout, FE model, targets.

``PlateModel`` is imported lazily so that :mod:`wingopt.problem.plate` can use the laminate helpers
without an import cycle.
"""

from wingopt.plate.laminate import (
    isotropic_stiffness,
    laminate_rigidity,
    plate_rigidity,
    reduced_stiffness,
    rotate,
    symmetric_pair_rigidity,
)

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


def __getattr__(name: str):
    if name in ("PlateModel", "plate_space"):
        from wingopt.plate import model

        return getattr(model, name)
    raise AttributeError(f"module 'wingopt.plate' has no attribute {name!r}")
