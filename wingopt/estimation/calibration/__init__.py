"""Calibration of a membrane's tension and damping from a record without load (release, pluck, tap)."""

from wingopt.estimation.calibration.fit import Calibration, calibrate

__all__ = ["Calibration", "calibrate"]
