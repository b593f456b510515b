"""Membrane wing: FE model, stretch sensors, load cases and simulation (chapter 6)."""

from wingopt.membrane.loads import LOAD_CASES, PressureLoad, bubble, load_case
from wingopt.membrane.model import MembraneModel, membrane_space
from wingopt.membrane.sensors import StretchSensors, add_noise, noise_std_for
from wingopt.membrane.simulation import Trajectory, simulate_response

__all__ = [
    "MembraneModel",
    "membrane_space",
    "StretchSensors",
    "add_noise",
    "noise_std_for",
    "PressureLoad",
    "load_case",
    "bubble",
    "LOAD_CASES",
    "Trajectory",
    "simulate_response",
]
