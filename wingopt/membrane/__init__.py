"""Membrane wing: FE model, stretch sensors, load cases and simulation (chapter 6).

Geometrically nonlinear membranes (spec §8): :class:`FvKMembrane` (Föppl–von Kármán, the truth
generator), :class:`CubicModalMembrane` (FvK's exact cubic stiffness on the lowest modes, fast),
:class:`BergerMembrane` (uniform tension, fastest) and
:func:`simulate_record` (simulated sensor records from either).
"""

from wingopt.membrane.berger import BergerMembrane
from wingopt.membrane.berger_sim import BergerTrajectory, simulate_berger
from wingopt.membrane.fvk import FvKMembrane
from wingopt.membrane.fvk_modal import CubicModalMembrane
from wingopt.membrane.fvk_sim import simulate_fvk
from wingopt.membrane.loads import LOAD_CASES, PressureLoad, bubble, load_case
from wingopt.membrane.model import MembraneModel, membrane_space
from wingopt.membrane.nonlinear import AlphaSettings, MembraneParameters
from wingopt.membrane.records import Gust, NonlinearRecord, leading_edge_load, simulate_record, truth_load
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
    "MembraneParameters",
    "AlphaSettings",
    "FvKMembrane",
    "simulate_fvk",
    "CubicModalMembrane",
    "BergerMembrane",
    "BergerTrajectory",
    "simulate_berger",
    "Gust",
    "NonlinearRecord",
    "simulate_record",
    "truth_load",
    "leading_edge_load",
]
