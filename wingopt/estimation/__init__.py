"""Load identification on the membrane: measurements, simulated protocol, estimators."""

from wingopt.estimation.csv_data import read_measurements
from wingopt.estimation.data import IdentificationResult, Measurements
from wingopt.estimation.mhe import MHESettings, MovingHorizonEstimator, mhe_identify
from wingopt.estimation.protocol import TRUTH_NODES, SimulatedCase, relative_l2, simulate_case

__all__ = [
    "Measurements",
    "IdentificationResult",
    "SimulatedCase",
    "simulate_case",
    "relative_l2",
    "TRUTH_NODES",
    "MHESettings",
    "MovingHorizonEstimator",
    "mhe_identify",
    "read_measurements",
]
