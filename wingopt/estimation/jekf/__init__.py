"""The seed's joint extended Kalman filter (JEKF) as a baseline, with its two presets (chapter 6).

The load ``P ≈ Σ f_i phi_i`` (deflection basis, ``p = M f``) is appended to the membrane state as
a random walk, ``f' = 0 + noise``, and the joint state ``[z, z', f]`` is estimated by an extended
Kalman filter on the quadratic stretch sensors ``s_i = z^T C_i z`` (Jacobian rows ``2 z^T C_i``):

* joint transition ``F_hat = expm([[A, B], [0, 0]] dt)``: ONE augmented matrix exponential
  (eq. 6.24), i.e. the exact zero-order hold of the plant with the load held over the step;
* process noise on the load block only, ``Qd`` per unit time: ``Qd = 0`` for static loads, Gelb's
  rule ``Qd_ii = Δf_i^2 / Δt`` (eq. 6.38) for a load expected to change by ``Δf`` over ``Δt``;
* Joseph-form covariance update (eq. 6.30);
* regularised initial covariance on the load block only (eqs. 6.44–6.46)::

      P0_d = (P0d_tilde^-1 + lambda Lam)^-1,     Lam = ∫ (phi_xx phi_xx^T + phi_yy phi_yy^T)

  With ``P0d_tilde = load_std^2 I`` and the default ``load_std = inf`` the prior on the load is the
  pure smoothness (Tikhonov) prior ``(lambda Lam)^-1``: ``lambda`` is then the only knob and the
  filter approximates ``min Σ |y_k - h(x_k)|^2_{R^-1} + lambda (f - f0)^T Lam (f - f0) + state prior``.

:mod:`~.settings` (configuration, seed and tuned presets), :mod:`~.filter` (the step-able
filter), :mod:`~.batch` (a whole record through it, ``JointEKF.run``), :mod:`~.seed_lambda` (the seed's
Nelder–Mead on the truth), :mod:`~.tuning` (data-only lambda rules), :mod:`~.presets` (the two
baselines as the command line and the studies run them).
"""

from wingopt.estimation.jekf.filter import JointEKF, joint_transition
from wingopt.estimation.jekf.presets import VARIANTS, identify, jekf_identify
from wingopt.estimation.jekf.seed_lambda import LambdaSearch, seed_lambda
from wingopt.estimation.jekf.settings import SEED_MEASUREMENT_VARIANCE, JEKFSettings
from wingopt.estimation.jekf.tuning import DEFAULT_GRID, LAMBDA_RULES, LambdaSelection, select_lambda, tuned_identify

__all__ = [
    "JEKFSettings",
    "JointEKF",
    "jekf_identify",
    "joint_transition",
    "SEED_MEASUREMENT_VARIANCE",
    "seed_lambda",
    "LambdaSearch",
    "select_lambda",
    "LambdaSelection",
    "tuned_identify",
    "identify",
    "VARIANTS",
    "DEFAULT_GRID",
    "LAMBDA_RULES",
]
