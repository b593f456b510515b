"""Full-order continuous LQR gains of the plate on large meshes: Newton–Kleinman with low-rank ADI.

The seed computed the gain of ``E x' = A x + B u`` (``x = [z; z']``, ``E = blockdiag(I, M)``,
``A = [[0, I], [-K, -Kd]]``, ``B = [0; b]``) from the dense algebraic Riccati equation and needed four
hours on 25x121 (6534 states). Here the generalised Riccati equation::

    A^T X E + E^T X A - E^T X B R^-1 B^T X E + C^T C = 0,      K = R^-1 B^T X E

is solved by Newton–Kleinman: from a stabilising gain ``K_i``, each step solves the Lyapunov
equation ``F^T X E + E^T X F = -(C^T C + K_i^T R K_i)`` with ``F = A - B K_i`` and sets
``K_{i+1} = R^-1 B^T X E``. The Lyapunov equations are solved by the residual-based low-rank ADI
iteration (Benner, Kürschner, Saak) in real arithmetic for complex shift pairs, on the sparse
pencil: each shift ``p`` needs one sparse LU of the ``n x n`` quadratic pencil ``p^2 M - p Kd + K``
(block elimination of ``A^T + p E``) and a rank-9 Sherman–Morrison–Woodbury correction for
``-K_i^T B^T``. The gain is accumulated on the fly (``B^T Z Z^T E``), the factor is never stored
beyond one cycle of shifts, and shifts are Ritz values of the closed-loop pencil on the lowest
modes, then on the span of the last ADI cycle (projection shifts). The first gain comes from the
Riccati equation of a modal reduction (dense, small), so Newton starts close and converges in a
few steps.

Where this applies. Low-rank ADI needs a low-rank weight ``C^T C``. The seed's weight
``Q = blockdiag(alpha M, beta M)`` is full rank, and with ``R = 1e-14 I`` the patches control every
mode up to the mesh's highest: the Riccati solution is then numerically full rank (7x31: all 558
singular values of ``X - X_open-loop`` within a factor 1e8 of the largest) and no low-rank method
can represent it. :func:`plate_weight` therefore builds the seed's weight restricted to the lowest
``weight_modes`` undamped modes, ``C = blockdiag(sqrt(alpha) Phi_N^T M, sqrt(beta) Phi_N^T M)``,
which is exactly the seed's ``Q`` on fields in that band and is the same weight on every mesh
(the band is set in Hz by the modes, not by the mesh), so the gains converge with the mesh. With
``weight_modes = n`` it *is* the seed's ``Q``; :func:`dense_care_gain` (Newton–Kleinman with dense
Lyapunov solves in the eigenbasis of energy-scaled modal coordinates; Riccati residual 1e-10 where
``scipy.linalg.solve_continuous_are`` leaves 2e-3 at ``r = 1e-10`` and O(1e4) at ``r = 1e-12`` on
7x31) is the reference for both.

Input weight. :data:`GAIN_R` = 1e-10, not the digital design's 1e-14: at 1e-14 the continuous
problem sits at the limit of double precision (gains of 1e7 in energy units, the dense Newton
iteration stalls at a Riccati residual of 6e-8 after 40 steps on 7x31 and NK-ADI diverges); at
1e-10 both converge.

Accuracy. The ADI residual levels off near 1e-9 on the lightly damped plate (every lightly damped
pair needs a shift close to it), so Newton is inexact and its gain change stalls near 1e-6; it
stops at a relative change of 1e-5. Measured against :func:`dense_care_gain` (20 weight modes):
relative gain error 3.2e-6 on 7x31 and 5.5e-5 on 13x61; 25x121 in 340 s on one core (``benchmarks/bench_lqr_large.py``).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from wingopt.errors import InputError, SolverError

__all__ = [
    "GAIN_R",
    "NKADIResult",
    "plate_weight",
    "care_nk_adi",
    "reduced_initial_gain",
    "dense_care_gain",
    "plate_lqr_gain",
    "gain_relative_error",
    "functional_gains",
    "gain_profiles",
]

log = logging.getLogger(__name__)

GAIN_R = 1e-10
"""Input weight ``R = r I`` of the continuous full-order gains (see the module docstring)."""

DEFAULT_WEIGHT_MODES = 20
"""Modes in the state weight of the continuous gains (up to 583 Hz on 7x31, 562 Hz on 25x121)."""


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


def gain_relative_error(K: np.ndarray, K_ref: np.ndarray) -> float:
    """``||K - K_ref||_F / ||K_ref||_F``."""
    return float(np.linalg.norm(K - K_ref) / np.linalg.norm(K_ref))


def _modes(model, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Lowest ``count`` undamped modes (rad/s, M-orthonormal shapes); dense when that is cheaper."""
    n = model.n
    count = int(min(count, n))
    if n <= 1200 or count > n // 3:
        lam, Phi = sla.eigh(model.stiffness.toarray(), model.mass.toarray(), subset_by_index=(0, count - 1))
        return np.sqrt(np.clip(lam, 0.0, None)), Phi
    return model.system.undamped_modes(count)


def plate_weight(
    model, alpha: float = 1.0, beta: float = 1.0, weight_modes: int | None = DEFAULT_WEIGHT_MODES
) -> np.ndarray:
    """Factor ``C`` (2N x 2n) of the band-limited seed weight ``C^T C`` on ``x = [z; z']``.

    ``C = blockdiag(sqrt(alpha) Phi_N^T M, sqrt(beta) Phi_N^T M)``: ``||C x||^2`` is
    ``alpha ||P z||_M^2 + beta ||P z'||_M^2`` with ``P`` the M-orthogonal projector onto the lowest
    ``N = weight_modes`` modes (``None``: all modes, the seed's full ``Q``).
    """
    n = model.n
    N = n if weight_modes is None else int(weight_modes)
    if not 1 <= N <= n:
        raise InputError(f"weight_modes = {weight_modes!r}: expected 1..{n}")
    _, Phi = _modes(model, N)
    PM = np.asarray((model.mass @ Phi).T)
    C = np.zeros((2 * N, 2 * n))
    C[:N, :n] = np.sqrt(alpha) * PM
    C[N:, n:] = np.sqrt(beta) * PM
    return C


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
    """Stable Ritz values of the ADI pencil ``(F^T, E)``, ``F = A - B K``, on ``span U`` (U real, 2n x k)."""
    # Orthonormal basis of the numerically relevant part of span U (at most max_dim directions). A
    # full SVD of the cycle's factor (6534 x ~2000 on 25x121) dominated the run time; a randomised
    # range finder (Halko, Martinsson, Tropp 2011) with a fixed seed gives the leading directions at
    # a fraction of the cost, and the shifts only steer convergence (the residual is exact).
    if U.shape[1] > max_dim + 20:
        Omega = np.random.default_rng(0).standard_normal((U.shape[1], max_dim + 20))
        Qr, _ = np.linalg.qr(U @ (U.T @ (U @ Omega)))  # one power iteration
        Ub, sv, _ = np.linalg.svd(Qr.T @ U, full_matrices=False)
        Uq = Qr @ Ub
    else:
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
):
    """Residual-based real LR-ADI for ``F^T X E + E X F = -G G^T``; returns ``B^T X E`` (m x 2n).

    Real arithmetic for complex shifts (Benner, Kürschner, Saak 2013): one complex solve per pair.
    """
    n = solver.n
    W = np.array(G, dtype=float)
    g0 = float(np.sum(W**2))
    if g0 == 0:
        return np.zeros((solver.b.shape[1], 2 * n)), 0, 0.0
    acc = np.zeros((solver.b.shape[1], 2 * n))
    shifts = list(_ritz_shifts(solver, A_op, U0, K))
    steps = 0
    recent: list[np.ndarray] = []
    res = 1.0
    while steps < max_steps:
        if not shifts:
            if not recent:
                break
            shifts = list(_ritz_shifts(solver, A_op, np.hstack(recent), K))
            recent = []
            if not shifts:
                break
        p = shifts.pop(0)
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
        recent.append(Z)
        steps += 1
        res = float(np.sum(W**2)) / g0
        if res < tol:
            break
        if len(recent) >= cycle and not shifts:
            shifts = list(_ritz_shifts(solver, A_op, np.hstack(recent), K))
            recent = []
    solver.clear()
    return acc, steps, res


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
    """
    t0 = time.perf_counter()
    n = M.shape[0]
    b = np.asarray(b, dtype=float)
    m = b.shape[1]
    R = np.atleast_2d(np.asarray(R, dtype=float))
    if R.shape != (m, m) or np.linalg.eigvalsh(0.5 * (R + R.T)).min() <= 0:
        raise InputError(f"R: expected a symmetric positive definite ({m}, {m}) weight")
    C = np.atleast_2d(np.asarray(C, dtype=float))
    if C.shape[1] != 2 * n:
        raise InputError(f"C: shape {C.shape}, expected (p, {2 * n})")
    solver = _ShiftedSolver(M, D, Kst, b)
    Msp, Dsp, Ksp = solver.M, solver.D, solver.Kst

    def A_op(X):  # A^T X for A = [[0, I], [-K, -D]] (K, D symmetric)
        return np.vstack([-(Ksp @ X[n:]), X[:n] - Dsp @ X[n:]])

    # First projection space: the lowest modes, as displacement and as velocity fields.
    s = int(min(shift_modes, n - 1))
    _, Phi = (
        spla.eigsh(Ksp, k=s, M=Msp, sigma=0.0, which="LM", v0=np.ones(n))
        if n > 200
        else sla.eigh(Ksp.toarray(), Msp.toarray(), subset_by_index=(0, s - 1))
    )
    U0 = np.zeros((2 * n, 2 * s))
    U0[:n, :s] = Phi
    U0[n:, s:] = Phi
    Rch = np.linalg.cholesky(0.5 * (R + R.T))
    Rinv = np.linalg.inv(R)
    K = np.zeros((m, 2 * n)) if K0 is None else np.asarray(K0, dtype=float).copy()
    out = NKADIResult(K=K)
    for it in range(max_newton):
        G = np.hstack([C.T, K.T @ Rch])  # C^T C + K^T R K = G G^T
        acc, steps, res = _adi_gain(solver, A_op, K, G, U0, tol=adi_tol, max_steps=max_adi)
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
    out.factorizations = solver.factorizations
    out.wall_s = time.perf_counter() - t0
    if not out.converged:
        log.warning("NK-ADI: gain change %.2e after %d Newton steps (tol %.0e)", change, out.newton_steps, tol)
    return out


# -- initial gain and dense reference ---------------------------------------------------------------


def _energy_modal(model, count: int, alpha: float, beta: float, weight_modes: int | None):
    """Energy-scaled modal form of the lowest ``count`` modes: ``x_e = [Omega q; q']``."""
    omega, Phi = _modes(model, count)
    Dm = Phi.T @ (model.damping @ Phi)
    r = omega.size
    A = np.block([[np.zeros((r, r)), np.diag(omega)], [-np.diag(omega), -0.5 * (Dm + Dm.T)]])
    B = np.vstack([np.zeros((r, model.n_inputs)), Phi.T @ model.actuation])
    N = r if weight_modes is None else min(int(weight_modes), r)
    w = np.zeros(2 * r)
    w[:N] = alpha / omega[:N] ** 2
    w[r : r + N] = beta
    return A, B, w, omega, Phi


def _to_physical(model, Ke: np.ndarray, omega: np.ndarray, Phi: np.ndarray) -> np.ndarray:
    """Gain on ``x_e = [Omega Phi^T M z; Phi^T M z']`` -> gain on ``x = [z; z']``."""
    r = omega.size
    PM = np.asarray((model.mass @ Phi).T)
    return np.hstack([(Ke[:, :r] * omega) @ PM, Ke[:, r:] @ PM])


def _lyap_eig(F: np.ndarray, W: np.ndarray) -> np.ndarray:
    """``F^T X + X F = -W`` through the eigendecomposition of ``F`` (elementwise in its eigenbasis).

    ``scipy.linalg.solve_continuous_lyapunov`` perturbs the problem when two eigenvalues nearly
    cancel relative to ``||F||`` — here every lightly damped mode pairs with its conjugate
    (``2 Re(lambda) ~ -0.6`` against ``||F|| ~ 1e6``) — and the Newton iteration then stalls near
    1e-6; the eigenbasis is well conditioned (cond 2e2–2e3 on 7x31) and solves it exactly.
    """
    lam, V = np.linalg.eig(F)
    Vi = np.linalg.inv(V)
    Wt = V.conj().T @ W @ V
    Xt = -Wt / (lam.conj()[:, None] + lam[None, :])
    X = (Vi.conj().T @ Xt @ Vi).real
    return 0.5 * (X + X.T)


def _nk_dense(A, B, Qdiag, R, K0=None, tol=1e-12, max_newton=60):
    """Dense Newton–Kleinman (standard form) with eigenbasis Lyapunov solves."""
    K = np.zeros((B.shape[1], A.shape[0])) if K0 is None else K0.copy()
    Q = np.diag(Qdiag)
    steps, change = 0, np.inf
    X = np.zeros_like(A)
    for steps in range(1, max_newton + 1):  # noqa: B007 (steps is returned)
        X = _lyap_eig(A - B @ K, Q + K.T @ R @ K)
        K_new = np.linalg.solve(R, B.T @ X)
        change = np.linalg.norm(K_new - K) / max(np.linalg.norm(K_new), 1e-300)
        K = K_new
        if change < tol:
            break
    return K, X, steps, change


def reduced_initial_gain(
    model,
    r: float,
    alpha: float = 1.0,
    beta: float = 1.0,
    weight_modes: int | None = DEFAULT_WEIGHT_MODES,
    modes: int | None = None,
) -> np.ndarray:
    """Initial gain from the Riccati equation of the lowest modes (dense), on ``x = [z; z']``.

    ``modes`` defaults to ``weight_modes + 40``: the weighted band plus the modes it couples to.
    """
    count = (int(weight_modes) + 40 if weight_modes is not None else 120) if modes is None else int(modes)
    count = min(count, model.n)
    A, B, w, omega, Phi = _energy_modal(model, count, alpha, beta, weight_modes)
    Ke, _, _, _ = _nk_dense(A, B, w, r * np.eye(B.shape[1]), tol=1e-10)
    return _to_physical(model, Ke, omega, Phi)


def dense_care_gain(
    model, r: float, alpha: float = 1.0, beta: float = 1.0, weight_modes: int | None = None, K0=None, tol=1e-12
) -> tuple[np.ndarray, dict]:
    """Reference gain from the full dense Riccati equation (all ``n`` modes, energy-scaled modal form).

    Newton–Kleinman with dense Lyapunov solves in the closed loop's eigenbasis, started from ``K0`` (a gain on
    ``x = [z; z']``, mapped to the modal form) or from zero. Returns ``(K, info)`` with the gain on
    ``x = [z; z']`` and the Riccati residual relative to ``||X||``.
    """
    t0 = time.perf_counter()
    A, B, w, omega, Phi = _energy_modal(model, model.n, alpha, beta, weight_modes)
    Kinit = None
    if K0 is not None:
        n = model.n
        Kinit = np.hstack([(K0[:, :n] @ Phi) / omega, K0[:, n:] @ Phi])
    R = r * np.eye(B.shape[1])
    Ke, X, steps, change = _nk_dense(A, B, w, R, Kinit, tol=tol)
    res = A.T @ X + X @ A - X @ B @ np.linalg.solve(R, B.T @ X) + np.diag(w)
    info = {
        "newton_steps": steps,
        "gain_change": float(change),
        "riccati_residual": float(np.abs(res).max() / np.abs(X).max()),
        "wall_s": time.perf_counter() - t0,
    }
    return _to_physical(model, Ke, omega, Phi), info


def plate_lqr_gain(
    model,
    r: float | None = None,
    alpha: float = 1.0,
    beta: float = 1.0,
    weight_modes: int | None = DEFAULT_WEIGHT_MODES,
    method: str = "nk-adi",
    **kw,
) -> tuple[np.ndarray, dict]:
    """Continuous full-order LQR gain ``K`` (9 x 2n, on ``x = [z; z']``) of the seed's problem.

    ``method="nk-adi"`` (:func:`care_nk_adi` from :func:`reduced_initial_gain`) or ``"dense"``
    (:func:`dense_care_gain`). Returns ``(K, info)``.
    """
    r = GAIN_R if r is None else float(r)
    t0 = time.perf_counter()
    if method == "dense":
        K, info = dense_care_gain(model, r, alpha, beta, weight_modes, **kw)
        info.update(method="dense", total_s=time.perf_counter() - t0)
        return K, info
    if method != "nk-adi":
        raise InputError(f"method = {method!r}: expected nk-adi or dense")
    if weight_modes is None:
        raise InputError("weight_modes = None: the full seed weight is not low rank; use method='dense'")
    K0 = reduced_initial_gain(model, r, alpha, beta, weight_modes)
    t_init = time.perf_counter() - t0
    C = plate_weight(model, alpha, beta, weight_modes)
    res = care_nk_adi(
        model.mass, model.damping, model.stiffness, model.actuation, C, r * np.eye(model.n_inputs), K0, **kw
    )
    res.initial_gain_s = t_init
    info = {
        "method": "nk-adi",
        "newton_steps": res.newton_steps,
        "adi_steps": res.adi_steps,
        "gain_changes": res.gain_changes,
        "adi_residuals": res.adi_residuals,
        "factorizations": res.factorizations,
        "converged": res.converged,
        "stop_reason": res.stop_reason,
        "initial_gain_s": t_init,
        "total_s": time.perf_counter() - t0,
    }
    return res.K, info


def functional_gains(model, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bending and velocity functional gains of eq. 5.29, ``[k_b k_v] = blockdiag(K, M)^-T K_c^T``.

    ``K_c = [K_z, K_v]`` (9 x 2n) is the feedback gain on ``x = [z; z']``; the representers are
    ``k_b = K^-1 K_z^T`` (the gain as a field in the bending-energy inner product:
    ``K_z z = a(k_b, z) = ∫ kappa(k_b)^T D kappa(z)``) and ``k_v = M^-1 K_v^T`` (in the mass inner
    product: ``K_v z' = ∫ rho_h k_v z'``). Returns coefficient arrays ``(n, 9)`` each; a converged
    control law has mesh-independent fields.
    """
    n = model.n
    kb = spla.splu(sp.csc_matrix(model.stiffness)).solve(np.ascontiguousarray(K[:, :n].T))
    kv = spla.splu(sp.csc_matrix(model.mass)).solve(np.ascontiguousarray(K[:, n:].T))
    return kb, kv


def gain_profiles(model, K: np.ndarray, patches=(0, 3, 6), samples: int = 241) -> dict:
    """Functional gains along the mid-chord line ``x = W/2`` (the seed's Figs. 5.12–5.17).

    Returns ``{"y": (samples,), "bending": (len(patches), samples), "velocity": (...)}`` with the
    bending gain as its spanwise curvature ``d^2 k_b / dy^2`` (the seed plots the bending gains
    "with the second spatial derivatives of the basis functions") and the velocity gain ``k_v``.
    """
    kb, kv = functional_gains(model, K)
    y = np.linspace(0.0, model.problem.length, samples)
    x = np.full_like(y, 0.5 * model.problem.width)
    idx = list(patches)
    return {
        "y": y,
        "patches": [model.patch_names[i] for i in idx],
        "bending": np.stack([model.evaluate(kb[:, i], x, y, 0, 2) for i in idx]),
        "velocity": np.stack([model.evaluate(kv[:, i], x, y) for i in idx]),
    }
