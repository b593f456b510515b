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


def _matrix(name: str, value, ndim: int = 2) -> np.ndarray:
    """``value`` as a real float matrix (a scalar or vector made 2-D only for the weights)."""
    try:
        arr = np.asarray(value)
    except Exception:  # noqa: BLE001 - anything numpy cannot read is the caller's mistake
        arr = None
    if arr is None or arr.dtype.kind not in "biuf":
        what = "complex" if arr is not None and arr.dtype.kind == "c" else type(value).__name__
        raise InputError(f"{name}: got {what}: expected a real matrix of numbers")
    arr = arr.astype(float)
    if ndim == 0:
        arr = np.atleast_2d(arr)
    if arr.ndim != 2:
        raise InputError(f"{name}: {arr.ndim}-D array of shape {arr.shape}: expected a 2-D matrix")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name}: holds NaN or inf: expected finite numbers")
    return arr


def _system_matrices(args) -> tuple[np.ndarray, np.ndarray, tuple]:
    if not args:
        raise InputError("expected lqr(sys, Q, R[, N]) or lqr(A, B, Q, R[, N]): no arguments given")
    if isinstance(args[0], StateSpace) or (hasattr(args[0], "A") and hasattr(args[0], "B")):
        A, B, rest = _matrix("A", args[0].A), _matrix("B", args[0].B), args[1:]
    elif len(args) < 4:
        raise InputError(
            f"expected lqr(sys, Q, R[, N]) or lqr(A, B, Q, R[, N]): got {len(args)} argument(s) (B, Q, R missing?)"
        )
    else:
        A, B, rest = _matrix("A", args[0]), _matrix("B", args[1]), args[2:]
    if A.shape[0] != A.shape[1]:
        raise InputError(f"A: shape {A.shape}, expected a square matrix")
    if B.shape[0] != A.shape[0]:
        raise InputError(f"B: shape {B.shape}, expected ({A.shape[0]}, m): one row per state of A {A.shape}")
    return A, B, rest


def _weights(A, B, rest):
    if len(rest) not in (2, 3):
        raise InputError("expected lqr(sys, Q, R[, N]) or lqr(A, B, Q, R[, N])")
    Q = _matrix("Q", rest[0], ndim=0)
    R = _matrix("R", rest[1], ndim=0)
    N = _matrix("N", rest[2], ndim=0) if len(rest) == 3 else np.zeros((A.shape[0], B.shape[1]))
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


def _estimator_matrices(A, G, C, QN):
    A, G, C, QN = _matrix("A", A), _matrix("G", G), _matrix("C", C), _matrix("QN", QN, ndim=0)
    n = A.shape[0]
    if A.shape != (n, n) or G.shape[0] != n or C.shape[1] != n or QN.shape != (G.shape[1], G.shape[1]):
        raise InputError(
            f"shapes A {A.shape}, G {G.shape}, C {C.shape}, QN {QN.shape}: expected A (n, n), G (n, g), C (p, n), "
            "QN (g, g)"
        )
    return A, G, C, QN


def lqe(A, G, C, QN, RN):
    """Steady-state Kalman gain of ``x' = Ax + Gw, y = Cx + v`` (``E ww' = QN, E vv' = RN``).

    Returns ``L, P, E``: gain of ``x_hat' = A x_hat + L (y - C x_hat)``, error covariance, and
    the eigenvalues of ``A - L C``.
    """
    A, G, C, QN = _estimator_matrices(A, G, C, QN)
    K, P, _ = lqr(A.T, C.T, G @ QN @ G.T, RN)
    L = K.T
    return L, P, np.linalg.eigvals(A - L @ C)


def dlqe(A, G, C, QN, RN):
    """Discrete steady-state Kalman filter: returns ``L, P, E`` with the *predictor* gain
    ``L = A P C' (C P C' + RN)^-1`` and ``P`` the a-priori error covariance."""
    A, G, C, QN = _estimator_matrices(A, G, C, QN)
    K, P, _ = dlqr(A.T, C.T, G @ QN @ G.T, RN)
    L = K.T
    return L, P, np.linalg.eigvals(A - L @ C)
