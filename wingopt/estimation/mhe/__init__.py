"""Moving-horizon Tikhonov estimation of the membrane load (spec §4).

Modules: :mod:`~.settings` (configuration), :mod:`~.model` (reduced modal model, window
responses), :mod:`~.window` (one window's least-squares problem), :mod:`~.solvers` (Gauss–Newton
window solvers), :mod:`~.start` (scan and sign), :mod:`~.startup` (lambda path, state prior,
onset, restarts), :mod:`~.information` (window prior, arrival cost, lift band),
:mod:`~.consistency` (chi-square tests), :mod:`~.load_model` (random walk), :mod:`~.estimator`
(the step-able estimator).
"""

from wingopt.estimation.mhe.estimator import MovingHorizonEstimator, mhe_identify
from wingopt.estimation.mhe.settings import LOAD_MODELS, SIGN_MARGIN, STATE_PRIOR_EVIDENCE, MHESettings

__all__ = [
    "MHESettings",
    "MovingHorizonEstimator",
    "mhe_identify",
    "LOAD_MODELS",
    "STATE_PRIOR_EVIDENCE",
    "SIGN_MARGIN",
]
