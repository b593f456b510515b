"""The moving-horizon estimator (MHE) package: its modules and what it exports (spec §4).

Modules: :mod:`~.settings` (configuration), :mod:`~.model` (reduced modal model, window
responses), :mod:`~.window` (one window's least-squares problem), :mod:`~.solvers` (Gauss–Newton
window solvers), :mod:`~.record` (the checked, weighted record), :mod:`~.start` (priors, scan and
sign), :mod:`~.lambda_path` (lambda on the first window), :mod:`~.startup` (the start-up object:
state prior, lambda, onset, restarts), :mod:`~.information` (the window prior object: arrival
cost, lift band), :mod:`~.consistency` (chi-square tests), :mod:`~.load_model` (random walk),
:mod:`~.estimator` (the step-able estimator, which holds a window prior and a start-up).
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
