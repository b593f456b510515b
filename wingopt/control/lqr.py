"""Linear-quadratic regulators and estimators in the python-control style.

``lqr(sys, Q, R) -> K, S, E`` with ``u = -K x``, ``S`` the Riccati solution and ``E`` the
closed-loop eigenvalues; ``dlqr`` for discrete systems; ``lqe``/``dlqe`` for the steady-state
Kalman gain (by duality).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from wingopt.dynamics import StateSpace
from wingopt.errors import InputError, SolverError

__all__ = ["lqr", "dlqr", "lqe", "dlqe"]


def _system_matrices(args) -> tuple[np.ndarray, np.ndarray, tuple]:
    if isinstance(args[0], StateSpace):
        return args[0].A, args[0].B, args[1:]
    return np.asarray(args[0], float), np.asarray(args[1], float), args[2:]


def _weights(A, B, rest):
    if len(rest) not in (2, 3):
        raise InputError("expected lqr(sys, Q, R[, N]) or lqr(A, B, Q, R[, N])")
    Q = np.atleast_2d(np.asarray(rest[0], float))
    R = np.atleast_2d(np.asarray(rest[1], float))
    N = np.atleast_2d(np.asarray(rest[2], float)) if len(rest) == 3 else np.zeros((A.shape[0], B.shape[1]))
    n, m = B.shape
    for name, mat, shape in (("Q", Q, (n, n)), ("R", R, (m, m)), ("N", N, (n, m))):
        if mat.shape != shape:
            raise InputError(f"{name}: shape {mat.shape}, expected {shape}")
    if np.linalg.eigvalsh(0.5 * (R + R.T)).min() <= 0:
        raise InputError("R: expected a symmetric positive definite input weight")
    return Q, R, N


def lqr(*args):
    """Continuous-time LQR: minimise ``∫ x'Qx + u'Ru + 2x'Nu`` for ``x' = Ax + Bu``.

    Parameters
    ----------
    sys : StateSpace, or A, B : ndarray
    Q, R : ndarray
        State and input weights (``R`` positive definite).
    N : ndarray, optional
        Cross weight.

    Returns
    -------
    K : ndarray (m, n)
        Gain of ``u = -K x``.
    S : ndarray (n, n)
        Stabilising solution of the algebraic Riccati equation.
    E : ndarray (n,)
        Closed-loop eigenvalues of ``A - B K``.
    """
    A, B, rest = _system_matrices(args)
    Q, R, N = _weights(A, B, rest)
    try:
        S = sla.solve_continuous_are(A, B, Q, R, s=N)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise SolverError("scipy.solve_continuous_are", str(exc), "check stabilisability of (A, B)") from None
    K = np.linalg.solve(R, B.T @ S + N.T)
    return K, S, np.linalg.eigvals(A - B @ K)


def dlqr(*args):
    """Discrete-time LQR for ``x_{k+1} = A x_k + B u_k``; same returns as :func:`lqr`."""
    A, B, rest = _system_matrices(args)
    Q, R, N = _weights(A, B, rest)
    try:
        S = sla.solve_discrete_are(A, B, Q, R, s=N)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise SolverError("scipy.solve_discrete_are", str(exc), "check stabilisability of (A, B)") from None
    K = np.linalg.solve(R + B.T @ S @ B, B.T @ S @ A + N.T)
    return K, S, np.linalg.eigvals(A - B @ K)


def lqe(A, G, C, QN, RN):
    """Steady-state Kalman gain of ``x' = Ax + Gw, y = Cx + v`` (``E ww' = QN, E vv' = RN``).

    Returns ``L, P, E``: gain of ``x_hat' = A x_hat + L (y - C x_hat)``, error covariance, and
    the eigenvalues of ``A - L C``.
    """
    A, G, C = (np.asarray(a, float) for a in (A, G, C))
    K, P, _ = lqr(A.T, C.T, G @ np.atleast_2d(QN) @ G.T, RN)
    L = K.T
    return L, P, np.linalg.eigvals(A - L @ C)


def dlqe(A, G, C, QN, RN):
    """Discrete steady-state Kalman filter: returns ``L, P, E`` with the *predictor* gain
    ``L = A P C' (C P C' + RN)^-1`` and ``P`` the a-priori error covariance."""
    A, G, C = (np.asarray(a, float) for a in (A, G, C))
    K, P, _ = dlqr(A.T, C.T, G @ np.atleast_2d(QN) @ G.T, RN)
    L = K.T
    return L, P, np.linalg.eigvals(A - L @ C)
