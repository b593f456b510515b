"""Accuracy guard for the dense Riccati solvers behind :func:`wingopt.control.lqr.lqr` and ``dlqr``.

``scipy.linalg.solve_continuous_are`` (Schur method on the Hamiltonian) can be silently wrong on
lightly damped structures with a small input weight: on the full-order 7x31 plate (558 states,
``Q = blockdiag(M, M)``, ``R = 1e-10 I``) it returns a gain 8e-4 off with a relative residual of
1.3e-4 and the slowest closed-loop pole at -2.62 instead of -1.80. Every solution is therefore
checked by its *relative residual* (the backward error)::

    ||A^T S + S A - S G S + Q||_F / (2 ||A^T S||_F + ||S G S||_F + ||Q||_F),   G = B R^-1 B^T

and, when it exceeds ``rtol``, refined by Newton–Kleinman from the Schur solution's gain in
rescaled coordinates: the real modal coordinates of ``A`` with unit-norm columns (for a
second-order structure these are the energy-scaled modal coordinates up to a diagonal scaling:
the physical coordinates ``[z; z']`` mix displacements and velocities that differ by the
frequency, ~1e5 on the plate, and the closed loop's eigenvector matrix has condition 1e8 there
against 1e7 in modal coordinates, enough to lose three digits). Each Newton step solves the
closed-loop Lyapunov equation in the closed loop's eigenbasis, which is exact where
``solve_continuous_lyapunov`` perturbs nearly cancelling eigenvalue pairs.

From a poor start Newton's method first converges *linearly*, halving the gain change per step
(the scalar picture: Newton on ``x^2 = a`` from ``x >> sqrt(a)``), before the quadratic phase. The
Schur gain of the 7x31 plate is such a start, and how poor depends on the LAPACK build (measured:
residual 1.3e-4, two Newton steps to 1.3e-9; or residual 2.0e-4, eight halving steps, then two
quadratic ones to 1.5e-9, gain 8e-9 from the energy-scaled modal reference). The iteration
therefore stops only when it has converged (residual below ``rtol``, gain change below
:data:`SETTLED`) or when the gain change stops shrinking (rounding level, or divergence), never
merely because it shrinks slowly. If the residual is then above ``rtol``,
:class:`~wingopt.errors.RiccatiAccuracyError` is raised; a gain is never returned silently
inaccurate. ``dlqr`` is checked the same way and refined by Hewer's discrete Newton iteration.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg as sla

from wingopt.errors import RiccatiAccuracyError

__all__ = ["RTOL", "SETTLED", "care_residual", "dare_residual", "refine_care", "refine_dare"]

log = logging.getLogger(__name__)

RTOL = 1e-8
"""Largest accepted relative Riccati residual (backward error) of ``lqr``/``dlqr``."""

SETTLED = 1e-6
"""Relative gain change below which a Newton iterate with an accepted residual has converged."""

_MAX_NEWTON = 20
_COND_MODAL = 1e10  # eigenvector condition above which A's modal coordinates are not used


def care_residual(A, B, Q, R, S) -> float:
    """Relative residual of ``A^T S + S A - S B R^-1 B^T S + Q = 0`` (standard form, no cross term)."""
    AS = A.T @ S
    SGS = S @ B @ np.linalg.solve(R, B.T @ S)
    res = AS + AS.T - SGS + Q
    scale = 2 * np.linalg.norm(AS) + np.linalg.norm(SGS) + np.linalg.norm(Q)
    return float(np.linalg.norm(res) / scale) if scale > 0 else 0.0


def dare_residual(A, B, Q, R, S) -> float:
    """Relative residual of ``A^T S A - S - A^T S B (R + B^T S B)^-1 B^T S A + Q = 0``."""
    ASA = A.T @ S @ A
    BSA = B.T @ S @ A
    T = BSA.T @ np.linalg.solve(R + B.T @ S @ B, BSA)
    res = ASA - S - T + Q
    scale = np.linalg.norm(ASA) + np.linalg.norm(S) + np.linalg.norm(T) + np.linalg.norm(Q)
    return float(np.linalg.norm(res) / scale) if scale > 0 else 0.0


def _stop(res: float, rtol: float, change: float, prev: float) -> bool:
    """Converged (residual accepted, gain settled), or stalled: the gain change no longer shrinks.

    A change that shrinks, however slowly (the halving phase from a poor start), is progress.
    """
    return (res <= rtol and change < SETTLED) or not change < prev


def _lyap(F: np.ndarray, W: np.ndarray) -> np.ndarray:
    """``F^T X + X F = -W``: in the eigenbasis of ``F`` when it is well conditioned, else Bartels–Stewart."""
    lam, V = np.linalg.eig(F)
    if np.linalg.cond(V) < 1e12:
        Vi = np.linalg.inv(V)
        Xt = -(V.conj().T @ W @ V) / (lam.conj()[:, None] + lam[None, :])
        X = (Vi.conj().T @ Xt @ Vi).real
    else:
        X = sla.solve_continuous_lyapunov(F.T, -W)
    return 0.5 * (X + X.T)


def _modal_coordinates(A: np.ndarray) -> np.ndarray | None:
    """Real modal basis of ``A`` with unit columns (``x = T x_m``), or None when ill conditioned."""
    try:
        lam, V = np.linalg.eig(A)
        _, T = sla.cdf2rdf(lam, V)
    except (np.linalg.LinAlgError, ValueError):
        return None
    T = T / np.linalg.norm(T, axis=0)
    return T if np.linalg.cond(T) < _COND_MODAL else None


def refine_care(A, B, Q, R, K0: np.ndarray, rtol: float = RTOL) -> tuple[np.ndarray, np.ndarray]:
    """Newton–Kleinman refinement of a stabilising gain ``K0`` (standard form); returns ``(S, K)``.

    Works in the real modal coordinates of ``A`` when they are well conditioned. Stops when the
    iterate has converged or the relative gain change stops shrinking (rounding level), and raises
    :class:`RiccatiAccuracyError` when the residual is then still above ``rtol``, after
    ``_MAX_NEWTON`` steps, or when ``K0`` does not stabilise.
    """
    T = _modal_coordinates(A)
    if T is not None:
        Am, Bm, Qm = np.linalg.solve(T, A @ T), np.linalg.solve(T, B), T.T @ Q @ T
        Qm = 0.5 * (Qm + Qm.T)
        K = K0 @ T
    else:
        Am, Bm, Qm, K = A, B, Q, K0
    if np.linalg.eigvals(Am - Bm @ K).real.max() >= 0:
        raise RiccatiAccuracyError("riccati refinement", "initial gain not stabilising", "check (A, B)")
    prev, X, res = np.inf, None, np.inf
    for it in range(1, _MAX_NEWTON + 1):
        X = _lyap(Am - Bm @ K, Qm + K.T @ R @ K)
        K_new = np.linalg.solve(R, Bm.T @ X)
        change = float(np.linalg.norm(K_new - K) / max(np.linalg.norm(K_new), 1e-300))
        K = K_new
        res = care_residual(Am, Bm, Qm, R, X)
        log.debug("Riccati refinement step %d: gain change %.2e, residual %.2e", it, change, res)
        if _stop(res, rtol, change, prev):
            break
        prev = change
    if not (res <= rtol and np.isfinite(res)):
        raise RiccatiAccuracyError(
            "riccati refinement",
            f"relative residual {res:.1e} > {rtol:.0e} after {it} Newton steps",
            "rescale the model (e.g. energy-scaled modal coordinates) or raise R",
        )
    log.info("Riccati solution refined by Newton–Kleinman (%d steps, relative residual %.1e)", it, res)
    if T is None:
        return X, np.linalg.solve(R, B.T @ X)
    # The gain maps back on its own (K = K_m T^-1): forming S = T^-T X T^-1 first would square
    # cond(T) into it (measured: 7e-7 against 6e-9 on the 7x31 plate).
    Ti = np.linalg.inv(T)
    S = Ti.T @ X @ Ti
    return 0.5 * (S + S.T), np.linalg.solve(R, Bm.T @ X) @ Ti


def refine_dare(A, B, Q, R, K0: np.ndarray, rtol: float = RTOL) -> np.ndarray:
    """Hewer's Newton iteration for the discrete Riccati equation from a stabilising ``K0``; returns ``S``."""
    if np.abs(np.linalg.eigvals(A - B @ K0)).max() >= 1:
        raise RiccatiAccuracyError("riccati refinement", "initial gain not stabilising", "check (A, B)")
    K, prev, S, res = K0, np.inf, None, np.inf
    for it in range(1, _MAX_NEWTON + 1):  # noqa: B007 (it is reported)
        F = A - B @ K
        S = sla.solve_discrete_lyapunov(F.T, Q + K.T @ R @ K)
        S = 0.5 * (S + S.T)
        K_new = np.linalg.solve(R + B.T @ S @ B, B.T @ S @ A)
        change = float(np.linalg.norm(K_new - K) / max(np.linalg.norm(K_new), 1e-300))
        K = K_new
        res = dare_residual(A, B, Q, R, S)
        if _stop(res, rtol, change, prev):
            break
        prev = change
    if not (res <= rtol and np.isfinite(res)):
        raise RiccatiAccuracyError(
            "riccati refinement", f"relative residual {res:.1e} > {rtol:.0e} after {it} Newton steps", "raise R"
        )
    return S
