"""State space: second-order FE systems, first-order form, exact ZOH, modal coordinates."""

from wingopt.dynamics.modal import DiscreteModalModel, ModalModel
from wingopt.dynamics.statespace import SecondOrderSystem, StateSpace, discretize, simulate, zoh

__all__ = [
    "StateSpace",
    "SecondOrderSystem",
    "zoh",
    "discretize",
    "simulate",
    "ModalModel",
    "DiscreteModalModel",
]
