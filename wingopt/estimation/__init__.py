"""Load identification on the membrane: measurements, noise level, load spaces, estimators.

Estimators share one shape (``setup / step / result``, a one-shot function beside): the
moving-horizon estimator (:mod:`wingopt.estimation.mhe`) and the seed's joint EKF as a baseline
(:mod:`wingopt.estimation.jekf`). Simulated protocols and the ``identify`` use case sit above, in
:mod:`wingopt.workflows`.
"""

from wingopt.estimation.csv_data import read_measurements
from wingopt.estimation.data import IdentificationResult, Measurements
from wingopt.estimation.mhe import MHESettings, MovingHorizonEstimator, mhe_identify

__all__ = [
    "Measurements",
    "IdentificationResult",
    "MHESettings",
    "MovingHorizonEstimator",
    "mhe_identify",
    "read_measurements",
]
