"""Newton–Kleinman with low-rank ADI for the generalised Riccati equation of a second-order structure.

Solves ``A^T X E + E^T X A - E^T X B R^-1 B^T X E + C^T C = 0`` for ``E x' = A x + B u`` with
``x = [z; z']``, ``E = blockdiag(I, M)``, ``A = [[0, I], [-K, -D]]``, ``B = [0; b]``, without forming
any dense ``2n x 2n`` matrix: from a stabilising gain ``K_i`` each Newton step solves
``F^T X E + E^T X F = -(C^T C + K_i^T R K_i)``, ``F = A - B K_i``, by the residual-based low-rank
ADI (Benner, Kürschner, Saak) in real arithmetic for complex shift pairs, and sets
``K_{i+1} = R^-1 B^T X E``. Each shift ``p`` needs one sparse LU of the ``n x n`` quadratic pencil
``p^2 M - p D + K`` (block elimination of ``A^T + p E``) and a rank-m Sherman–Morrison–Woodbury
correction for ``-K_i^T B^T``; the gain ``B^T Z Z^T E`` is accumulated on the fly and the factor is
never stored. Shifts are Ritz values of the closed-loop pencil on the lowest modes, then on a
randomised sketch of the last cycle's factor (projection shifts).

What makes it fast (issue 16, measured on the plate with the 20-mode weight, r = 1e-10):

* **Stopping at the gain's accuracy.** On the lightly damped plate the ADI residual levels off
  (1e-8 on 7x31, 5e-7 on 13x61) long before 1e-9, so every solve ran to its 800-shift cap; the
  accumulated gain, which is all Newton needs, settles after 80–120 shifts (later 40-shift cycles
  change it by 1e-6 in no consistent direction). The ADI now stops when a cycle changes the gain
  by less than ``gain_tol`` (default ``2 tol``).
* **One set of shifts per solve sequence.** Newton steps after the first replay the previous
  step's shifts (the closed loop moves by ~1e-3), so no projection eigenproblem is solved again.
* **A sketch instead of the stacked factor** for the projection shifts (:class:`_Sketch`).

13x61: 1600 -> 240 sparse LUs, CPU time 61.5 s -> 5.3 s, gain 7.5e-6 from the previous
solution; 25x121: 2400 -> 240 LUs, 426.6 s -> 31.0 s CPU under the same load, 7.8e-6 from the
previous solution; 7x31: 2.6e-5 from the dense reference (``benchmarks/bench_lqr_large.py``).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from wingopt.dynamics import SecondOrderSystem
from wingopt.errors import InputError, SolverError

__all__ = ["NKADIResult", "care_nk_adi"]

log = logging.getLogger(__name__)


@dataclass
class NKADIResult:
    """Gain of a Newton–Kleinman–ADI solve and its convergence record.

    Attributes
    ----------
    K : ndarray (m, 2n)
        Gain of ``u = -K x`` in the coordinates ``x = [z; z']``.
    newton_steps : int
    adi_steps : list of int
        ADI shifts used in each Newton step (a complex pair counts once).
    gain_changes : list of float
        ``||K_{i+1} - K_i||_F / ||K_{i+1}||_F`` per Newton step.
    adi_residuals : list of float
        Final relative Lyapunov residual ``||W||_F^2 / ||G||_F^2`` per Newton step.
    factorizations : int
        Sparse LU factorizations (one per distinct shift).
    wall_s : float
    converged : bool
        The gain change fell below ``tol``, or below ``10 tol`` and stopped shrinking (the inexact
        Newton iteration has reached the accuracy of its ADI solves); ``stop_reason`` says which.
    """

    K: np.ndarray
    newton_steps: int = 0
    adi_steps: list = field(default_factory=list)
    gain_changes: list = field(default_factory=list)
    adi_residuals: list = field(default_factory=list)
    factorizations: int = 0
    wall_s: float = 0.0
    converged: bool = False
    stop_reason: str = "max_newton"
    initial_gain_s: float = 0.0


# -- the low-rank ADI on the sparse second-order pencil ---------------------------------------------


class _ShiftedSolver:
    """Solves ``(A^T + p E - K^T B^T) v = w`` for the plate pencil (block elimination + SMW)."""

    def __init__(self, M, D, Kst, b) -> None:
        self.M, self.D, self.Kst = (sp.csc_matrix(a) for a in (M, D, Kst))
        self.b = np.asarray(b, dtype=float)
        self.n = self.M.shape[0]
        self._lu: dict = {}
        self.factorizations = 0

    def _lu_of(self, p: complex):
        key = complex(p)
        if key not in self._lu:
            cplx = key.imag != 0
            P = (
                (key**2) * self.M - key * self.D + self.Kst
                if cplx
                else key.real**2 * self.M - key.real * self.D + self.Kst
            )
            # Each shift serves one ADI step (two solves), so only the latest factor is kept: a
            # cache of every shift's LU grew to ~8 GB on 25x121.
            self._lu.clear()
            self._lu[key] = (spla.splu(sp.csc_matrix(P)), cplx)
            self.factorizations += 1
        return self._lu[key]

    def clear(self) -> None:
        self._lu.clear()

    def solve_S(self, p: complex, w: np.ndarray) -> np.ndarray:
        """``(A^T + p E)^-1 w`` with ``A^T + p E = [[p I, -K], [I, p M - D]]``."""
        n = self.n
        lu, cplx = self._lu_of(p)
        if not cplx:
            p = p.real
        w1, w2 = w[:n], w[n:]
        rhs = p * w2 - w1
        if np.iscomplexobj(rhs) and not cplx:
            x2 = lu.solve(np.ascontiguousarray(rhs.real)) + 1j * lu.solve(np.ascontiguousarray(rhs.imag))
        else:
            x2 = lu.solve(np.ascontiguousarray(rhs))
        x1 = w2 - (p * (self.M @ x2) - self.D @ x2)
        return np.vstack([x1, x2]) if x1.ndim == 2 else np.concatenate([x1, x2])

    def solve(self, p: complex, K: np.ndarray, w: np.ndarray, SK: np.ndarray | None = None) -> np.ndarray:
        """``(A^T + p E - K^T B^T)^-1 w`` (Sherman–Morrison–Woodbury on the rank-m term)."""
        n = self.n
        Sw = self.solve_S(p, w)
        if not np.any(K):
            return Sw
        if SK is None:
            SK = self.solve_S(p, K.T.astype(complex if np.iscomplexobj(Sw) else float))
        cap = np.eye(K.shape[0]) - self.b.T @ SK[n:]
        return Sw + SK @ np.linalg.solve(cap, self.b.T @ Sw[n:])


def _E(M, x: np.ndarray) -> np.ndarray:
    n = M.shape[0]
    return np.concatenate([x[:n], M @ x[n:]]) if x.ndim == 1 else np.vstack([x[:n], M @ x[n:]])


def _ritz_shifts(solver: _ShiftedSolver, AT_op, U: np.ndarray, K: np.ndarray, max_dim: int = 400) -> np.ndarray:
    """Stable Ritz values of the ADI pencil ``(F^T, E)``, ``F = A - B K``, on ``span U`` (U real, 2n x k).

    ``U`` is either a basis (the first cycle's lowest modes) or a randomised sketch of the last
    cycle's factor (:class:`_Sketch`); its numerically relevant directions (at most ``max_dim``) are kept.
    """
    Uq, sv, _ = np.linalg.svd(U, full_matrices=False)
    keep = min(int(np.count_nonzero(sv > 1e-10 * sv[0])), max_dim)
    Q = Uq[:, :keep]
    AQ = AT_op(Q) - K.T @ (solver.b.T @ Q[solver.n :])
    EQ = _E(solver.M, Q)
    vals = sla.eigvals(Q.T @ AQ, Q.T @ EQ)
    vals = vals[np.isfinite(vals) & (vals.real < 0)]
    # One representative per conjugate pair (Im >= 0); the complex ADI step covers its conjugate.
    vals = vals[vals.imag >= -1e-12 * np.abs(vals)]
    vals = np.where(np.abs(vals.imag) <= 1e-10 * np.abs(vals), vals.real + 0j, vals)
    return vals[np.argsort(-np.abs(vals.real) / np.abs(vals))]  # best damped first


class _Sketch:
    """Randomised range sketch ``Y = [Z_1 .. Z_k] Omega`` of an ADI cycle's factor, built as it grows.

    The projection shifts need the leading directions of the cycle's factor (2n x ~4000 on 13x61).
    Stacking the factor and sketching it afterwards (Halko, Martinsson, Tropp 2011) cost 45 % of
    the run time on 13x61 (the stack, three products with it and an SVD); summing ``Z_i Omega_i``
    per step gives the same sketch at the cost of one thin product per step, and nothing is stored.
    """

    def __init__(self, rows: int, width: int = 420, seed: int = 0) -> None:
        self.rng = np.random.default_rng(seed)
        self.Y = np.zeros((rows, width))
        self.count = 0

    def add(self, Z: np.ndarray) -> None:
        self.Y += Z @ self.rng.standard_normal((Z.shape[1], self.Y.shape[1]))
        self.count += 1

    def take(self) -> np.ndarray:
        Y, self.Y, self.count = self.Y, np.zeros_like(self.Y), 0
        return Y


def _adi_gain(
    solver: _ShiftedSolver,
    A_op,
    K: np.ndarray,
    G: np.ndarray,
    U0: np.ndarray,
    *,
    tol: float,
    max_steps: int,
    cycle: int = 40,
    gain_tol: float = 0.0,
    shifts0: list | None = None,
):
    """Residual-based real LR-ADI for ``F^T X E + E X F = -G G^T``; returns ``B^T X E`` (m x 2n).

    Real arithmetic for complex shifts (Benner, Kürschner, Saak 2013): one complex solve per pair.
    Stops at the relative residual ``tol``, after ``max_steps`` shifts, or when a whole cycle of
    shifts changed the accumulated gain by less than ``gain_tol`` (relative): the gain is what
    Newton needs, and on the lightly damped plate it settles long before the residual does.
    ``shifts0``: shifts to start with (e.g. the previous Newton step's), else Ritz values on ``U0``.
    Returns ``(gain, steps, residual, shifts_used)``.
    """
    n = solver.n
    W = np.array(G, dtype=float)
    g0 = float(np.sum(W**2))
    if g0 == 0:
        return np.zeros((solver.b.shape[1], 2 * n)), 0, 0.0, []
    acc = np.zeros((solver.b.shape[1], 2 * n))
    shifts = list(shifts0) if shifts0 else list(_ritz_shifts(solver, A_op, U0, K))
    used: list = []
    steps = 0
    sketch = _Sketch(2 * n)
    acc_cycle = acc.copy()
    res = 1.0
    while steps < max_steps:
        if not shifts:
            if not sketch.count:
                break
            shifts = list(_ritz_shifts(solver, A_op, sketch.take(), K))
            if not shifts:
                break
        p = shifts.pop(0)
        used.append(p)
        SK = solver.solve_S(p, K.T.astype(complex if p.imag != 0 else float))
        V = solver.solve(p, K, W.astype(complex) if p.imag != 0 else W, SK)
        if p.imag == 0:
            pr = p.real
            W = W - 2 * pr * _E(solver.M, V.real)
            Z = np.sqrt(-2 * pr) * V.real
        else:
            gamma = 2 * np.sqrt(-p.real)
            delta = p.real / p.imag
            Vr = V.real + delta * V.imag
            W = W + gamma**2 * _E(solver.M, Vr)
            Z = np.hstack([gamma * Vr, gamma * np.sqrt(delta**2 + 1) * V.imag])
        acc += (solver.b.T @ Z[n:]) @ _E(solver.M, Z).T
        sketch.add(Z)
        steps += 1
        res = float(np.sum(W**2)) / g0
        if res < tol:
            break
        if steps % cycle == 0:
            change = float(np.linalg.norm(acc - acc_cycle) / max(np.linalg.norm(acc), 1e-300))
            log.debug("ADI: %d shifts, residual %.1e, gain change over the cycle %.1e", steps, res, change)
            if change < gain_tol:
                break
            acc_cycle = acc.copy()
        if sketch.count >= cycle and not shifts:
            shifts = list(_ritz_shifts(solver, A_op, sketch.take(), K))
    solver.clear()
    return acc, steps, res, used


def care_nk_adi(
    M,
    D,
    Kst,
    b: np.ndarray,
    C: np.ndarray,
    R: np.ndarray,
    K0: np.ndarray | None = None,
    *,
    tol: float = 1e-5,
    adi_tol: float = 1e-9,
    max_newton: int = 15,
    max_adi: int = 800,
    shift_modes: int = 60,
    shift_basis: np.ndarray | None = None,
    gain_tol: float | None = None,
    reuse_shifts: bool = True,
) -> NKADIResult:
    """Newton–Kleinman with low-rank ADI for the plate's generalised Riccati equation.

    Parameters
    ----------
    M, D, Kst : sparse (n, n)
        Mass, damping and stiffness (``E = blockdiag(I, M)``, ``A = [[0, I], [-Kst, -D]]``).
    b : ndarray (n, m)
        Input matrix (``B = [0; b]``).
    C : ndarray (p, 2n)
        Low-rank weight factor, ``Q = C^T C`` (e.g. :func:`plate_weight`).
    R : ndarray (m, m)
        Input weight (positive definite).
    K0 : ndarray (m, 2n), optional
        Stabilising initial gain (default zero: the plate is stable in open loop).
    tol : float
        Newton stops when the relative gain change falls below ``tol``.
    adi_tol : float
        ADI stops when ``||W||_F^2 / ||G||_F^2`` (the relative Lyapunov residual) falls below it.
    shift_modes : int
        Lowest undamped modes spanning the first projection-shift space.
    shift_basis : ndarray (n, s), optional
        Those modes, when the caller has them (:func:`plate_lqr_gain` solves the pencil once).
    gain_tol : float, optional
        An ADI solve stops when a cycle of 40 shifts changes the gain by less than this (relative);
        default ``2 tol``. ``0`` runs to ``adi_tol`` or ``max_adi`` (the behaviour before issue 16).
    reuse_shifts : bool
        Newton steps after the first start from the shifts the previous step used (the closed
        loop moves by the gain change, 1e-3 relative), instead of new projection shifts.
    """
    t0 = time.perf_counter()
    n = M.shape[0]
    b, R, C = _checked_weights(b, R, C, n)
    solver = _ShiftedSolver(M, D, Kst, b)
    U0 = _first_shift_space(solver, shift_basis, shift_modes)
    K = np.zeros((b.shape[1], 2 * n)) if K0 is None else np.asarray(K0, dtype=float).copy()
    gain_tol = 2 * tol if gain_tol is None else gain_tol
    out = _newton(solver, C, R, K, U0, tol, adi_tol, max_newton, max_adi, gain_tol, reuse_shifts)
    out.factorizations = solver.factorizations
    out.wall_s = time.perf_counter() - t0
    if not out.converged:
        change = out.gain_changes[-1]
        log.warning("NK-ADI: gain change %.2e after %d Newton steps (tol %.0e)", change, out.newton_steps, tol)
    return out


def _checked_weights(b, R, C, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``b``, ``R`` and ``C`` as float arrays, ``R`` symmetric positive definite and ``C`` on ``2 n`` states."""
    b = np.asarray(b, dtype=float)
    m = b.shape[1]
    R = np.atleast_2d(np.asarray(R, dtype=float))
    if R.shape != (m, m) or np.linalg.eigvalsh(0.5 * (R + R.T)).min() <= 0:
        raise InputError(f"R: expected a symmetric positive definite ({m}, {m}) weight")
    C = np.atleast_2d(np.asarray(C, dtype=float))
    if C.shape[1] != 2 * n:
        raise InputError(f"C: shape {C.shape}, expected (p, {2 * n})")
    return b, R, C


def _first_shift_space(solver: _ShiftedSolver, shift_basis, shift_modes: int) -> np.ndarray:
    """The first projection space: the lowest undamped modes, as displacement and as velocity fields."""
    n = solver.M.shape[0]
    if shift_basis is not None:
        Phi = np.asarray(shift_basis, dtype=float)
        s = Phi.shape[1]
    else:
        s = int(min(shift_modes, n - 1))
        _, Phi = SecondOrderSystem(solver.M, solver.D, solver.Kst, solver.b).undamped_modes(s)
    U0 = np.zeros((2 * n, 2 * s))
    U0[:n, :s] = Phi
    U0[n:, s:] = Phi
    return U0


def _newton(solver, C, R, K, U0, tol, adi_tol, max_newton, max_adi, gain_tol, reuse_shifts) -> NKADIResult:
    """Newton–Kleinman from the gain ``K``: one low-rank ADI Lyapunov solve per step, until the gain
    settles (``tol``) or stagnates at the ADI's accuracy."""
    n, Ksp, Dsp = solver.M.shape[0], solver.Kst, solver.D

    def A_op(X):  # A^T X for A = [[0, I], [-K, -D]] (K, D symmetric)
        return np.vstack([-(Ksp @ X[n:]), X[:n] - Dsp @ X[n:]])

    Rch, Rinv = np.linalg.cholesky(0.5 * (R + R.T)), np.linalg.inv(R)
    out = NKADIResult(K=K)
    shifts: list | None = None
    for it in range(max_newton):
        G = np.hstack([C.T, K.T @ Rch])  # C^T C + K^T R K = G G^T
        acc, steps, res, used = _adi_gain(
            solver,
            A_op,
            K,
            G,
            U0,
            tol=adi_tol,
            max_steps=max_adi,
            gain_tol=gain_tol,
            shifts0=shifts if reuse_shifts else None,
        )
        shifts = used
        K_new = Rinv @ acc
        change = float(np.linalg.norm(K_new - K) / max(np.linalg.norm(K_new), 1e-300))
        K = K_new
        out.adi_steps.append(steps)
        out.adi_residuals.append(res)
        out.gain_changes.append(change)
        log.info("NK-ADI step %d: %d shifts, ADI residual %.1e, gain change %.2e", it + 1, steps, res, change)
        if not np.all(np.isfinite(K)):
            raise SolverError("nk-adi", "diverged", "the initial gain may not stabilise the plate; try K0=None")
        if change < tol:
            out.converged, out.stop_reason = True, "tolerance"
            break
        # Inexact Newton: once the change stops shrinking it sits at the ADI's accuracy floor and
        # further steps only wander there (measured 7x31: 1.2e-5, 1.0e-5, 1.2e-5, 8e-6).
        prev = out.gain_changes[-2] if len(out.gain_changes) > 1 else np.inf
        if change < 10 * tol and change > 0.5 * prev:
            out.converged, out.stop_reason = True, "stagnation at the ADI accuracy"
            break
    out.K = K
    out.newton_steps = len(out.gain_changes)
    return out
