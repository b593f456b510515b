"""Load identification on the membrane: noise level, load spaces, estimators and their result.

Estimators share one shape (``setup / step / result``, a one-shot function beside): the
moving-horizon estimator (:mod:`wingopt.estimation.mhe`) and the seed's joint EKF as a baseline
(:mod:`wingopt.estimation.jekf`). What they consume is :class:`wingopt.measurements.Measurements`;
simulated protocols and the ``identify`` use case sit above, in :mod:`wingopt.workflows`.
"""

from wingopt.estimation.core.result import IdentificationResult
from wingopt.estimation.mhe import MHESettings, MovingHorizonEstimator, mhe_identify

__all__ = ["IdentificationResult", "MHESettings", "MovingHorizonEstimator", "mhe_identify"]
