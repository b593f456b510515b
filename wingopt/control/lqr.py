"""Linear-quadratic regulators and estimators in the python-control style.

``lqr(sys, Q, R) -> K, S, E`` with ``u = -K x``, ``S`` the Riccati solution and ``E`` the
closed-loop eigenvalues; ``dlqr`` for discrete systems; ``lqe``/``dlqe`` for the steady-state
Kalman gain (by duality). Every solution is checked by its relative residual and refined by
Newton's method when the Schur solver's is poor (:mod:`wingopt.control.riccati_refine`); a
solution that stays poor raises :class:`~wingopt.errors.RiccatiAccuracyError`.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg as sla

from wingopt.control.riccati_refine import RTOL, care_residual, dare_residual, refine_care, refine_dare
from wingopt.dynamics import StateSpace
from wingopt.errors import InputError, SolverError

__all__ = ["lqr", "dlqr", "lqe", "dlqe"]

log = logging.getLogger(__name__)


def _system_matrices(args) -> tuple[np.ndarray, np.ndarray, tuple]:
    if isinstance(args[0], StateSpace):
        return args[0].A, args[0].B, args[1:]
    if hasattr(args[0], "A") and hasattr(args[0], "B"):  # e.g. a python-control StateSpace
        return np.asarray(args[0].A, float), np.asarray(args[0].B, float), args[1:]
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


def lqr(*args, rtol: float = RTOL):
    """Continuous-time LQR: minimise ``∫ x'Qx + u'Ru + 2x'Nu`` for ``x' = Ax + Bu``.

    Parameters
    ----------
    sys : StateSpace, or A, B : ndarray
    Q, R : ndarray
        State and input weights (``R`` positive definite).
    N : ndarray, optional
        Cross weight.
    rtol : float
        Largest accepted relative Riccati residual (see :mod:`wingopt.control.riccati_refine`).

    Returns
    -------
    K : ndarray (m, n)
        Gain of ``u = -K x``.
    S : ndarray (n, n)
        Stabilising solution of the algebraic Riccati equation.
    E : ndarray (n,)
        Closed-loop eigenvalues of ``A - B K``.

    Raises
    ------
    RiccatiAccuracyError
        The residual stays above ``rtol`` after Newton refinement in modal coordinates.
    """
    A, B, rest = _system_matrices(args)
    Q, R, N = _weights(A, B, rest)
    # Standard form without the cross term: A1 = A - B R^-1 N', Q1 = Q - N R^-1 N' (same S).
    RiN = np.linalg.solve(R, N.T)
    A1, Q1 = A - B @ RiN, Q - N @ RiN
    Q1 = 0.5 * (Q1 + Q1.T)
    try:
        S = sla.solve_continuous_are(A, B, Q, R, s=N)
    except (np.linalg.LinAlgError, ValueError) as exc:
        if np.linalg.eigvals(A1).real.max() >= 0:
            raise SolverError("scipy.solve_continuous_are", str(exc), "check stabilisability of (A, B)") from None
        S = np.zeros_like(A)  # stable open loop: Newton from K = 0 below
    res = care_residual(A1, B, Q1, R, S)
    if res <= rtol:
        K = np.linalg.solve(R, B.T @ S + N.T)
    else:
        log.info("lqr: Schur solution's relative residual %.1e > %.0e, refining by Newton–Kleinman", res, rtol)
        S, K1 = refine_care(A1, B, Q1, R, np.linalg.solve(R, B.T @ S), rtol)
        K = K1 + RiN
    return K, S, np.linalg.eigvals(A - B @ K)


def dlqr(*args, rtol: float = RTOL):
    """Discrete-time LQR for ``x_{k+1} = A x_k + B u_k``, with the same checks as :func:`lqr`.

    Parameters
    ----------
    *args
        ``(sys, Q, R[, N])`` with a discrete :class:`~wingopt.dynamics.StateSpace` (or a
        python-control system), or ``(A, B, Q, R[, N])``.
    rtol : float
        Largest accepted relative residual of the Riccati solution; above it the solution is
        refined (Hewer's iteration), and :class:`~wingopt.errors.RiccatiAccuracyError` is raised if
        it stays above.

    Returns
    -------
    K : ndarray (m, n)
        Gain of ``u = -K x``.
    S : ndarray (n, n)
        Stabilising solution of the discrete algebraic Riccati equation.
    E : ndarray (n,)
        Closed-loop eigenvalues ``eig(A - B K)``.
    """
    A, B, rest = _system_matrices(args)
    Q, R, N = _weights(A, B, rest)
    try:
        S = sla.solve_discrete_are(A, B, Q, R, s=N)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise SolverError("scipy.solve_discrete_are", str(exc), "check stabilisability of (A, B)") from None
    RiN = np.linalg.solve(R, N.T)
    A1, Q1 = A - B @ RiN, Q - N @ RiN
    Q1 = 0.5 * (Q1 + Q1.T)
    res = dare_residual(A1, B, Q1, R, S)
    if not res <= rtol:
        log.info("dlqr: Schur solution's relative residual %.1e > %.0e, refining by Hewer's iteration", res, rtol)
        K1 = np.linalg.solve(R + B.T @ S @ B, B.T @ S @ A1)
        S = refine_dare(A1, B, Q1, R, K1, rtol)
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
