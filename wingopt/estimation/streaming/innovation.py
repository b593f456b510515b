"""The nonlinear stream's innovation covariance, kept positive definite.

The measurement update of :class:`~wingopt.estimation.streaming.nonlinear.NonlinearStreamingEstimator`
factors ``S = H Sigma H^T + R``. With ``R > 0`` it is positive definite in exact arithmetic; only
an unknowns' covariance ``Sigma`` that rounding made indefinite (a stated noise far below the
signal's) fails the factorisation. Then ``Sigma``'s negative eigenvalues are clipped, in place,
and counted: the filter's consistency test judges the fit that follows.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.linalg import lapack

__all__ = ["innovation"]

log = logging.getLogger(__name__)


def _factor(Sigma: np.ndarray, H: np.ndarray, r2: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    SH = Sigma @ H.T  # (d, p)
    S = H @ SH
    S[np.diag_indices_from(S)] += r2
    L, info = lapack.dpotrf(S, lower=1, clean=1)
    return L, SH, info


def innovation(Sigma: np.ndarray, H: np.ndarray, r2: np.ndarray, repairs: int) -> tuple[np.ndarray, np.ndarray, int]:
    """The lower Cholesky factor ``L`` of ``S = H Sigma H^T + diag(r2)`` and ``Sigma H^T``.

    ``H`` ``(p, d)``: the outputs' sensitivity to the unknowns; ``r2`` ``(p,)``: the noise
    variances; ``repairs``: the repairs of ``Sigma`` so far (the first one is logged), returned
    counted. Raises :class:`numpy.linalg.LinAlgError` when no repair makes ``S`` positive definite.
    """
    L, SH, info = _factor(Sigma, H, r2)
    if info == 0:
        return L, SH, repairs
    lam, V = np.linalg.eigh(0.5 * (Sigma + Sigma.T))
    Sigma[:] = (V * np.maximum(lam, 0.0)) @ V.T
    if repairs == 0:
        log.warning(
            "[ekf stream] the filter's covariance lost its positive definiteness to rounding and was "
            "repaired (a stated sensor noise far below the data's?); its consistency test judges the fit"
        )
    L, SH, info = _factor(Sigma, H, r2)
    if info != 0:
        raise np.linalg.LinAlgError("nonlinear streaming: innovation covariance not positive definite")
    return L, SH, repairs + 1
