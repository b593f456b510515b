"""Full-order continuous LQR gains of the plate on large meshes: Newton–Kleinman with low-rank ADI.

The seed computed the gain of ``E x' = A x + B u`` (``x = [z; z']``, ``E = blockdiag(I, M)``,
``A = [[0, I], [-K, -Kd]]``, ``B = [0; b]``) from the dense algebraic Riccati equation and needed four
hours on 25x121 (6534 states). Here the generalised Riccati equation::

    A^T X E + E^T X A - E^T X B R^-1 B^T X E + C^T C = 0,      K = R^-1 B^T X E

is solved by Newton–Kleinman with low-rank ADI on the sparse pencil
(:mod:`wingopt.control.riccati_adi`), started from the Riccati solution of a modal reduction
(dense, small) so that Newton converges in two steps. The lowest modes of the pencil, needed by
the weight, the initial gain and the first shift space, are solved once per model (:func:`_modes`).

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

Accuracy and time (issue 16; ``benchmarks/bench_lqr_large.py``, CPU time on one core). The ADI
stops once a 40-shift cycle changes the gain by less than ``2 tol`` (the residual levels off long
before its 1e-9 target on the lightly damped plate), and later Newton steps replay the first
step's shifts: 13x61 in 5.3 s CPU (was 61.5 s), 7.5e-6 from the previous solution (800 shifts per
Newton step); 7x31 2.6e-5 from :func:`dense_care_gain`. 25x121: see ``docs/control_lqr.md``.
"""

from __future__ import annotations

import logging
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from wingopt.control.riccati_adi import NKADIResult, _adi_gain, _ShiftedSolver, care_nk_adi  # noqa: F401 (re-exported)
from wingopt.errors import InputError

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


def gain_relative_error(K: np.ndarray, K_ref: np.ndarray) -> float:
    """``||K - K_ref||_F / ||K_ref||_F``."""
    return float(np.linalg.norm(K - K_ref) / np.linalg.norm(K_ref))


def _modes(model, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Lowest ``count`` undamped modes (rad/s, M-orthonormal shapes) from the model's mode cache.

    The weight, the initial gain and the first shift space all need the lowest modes of the same
    pencil; :meth:`~wingopt.dynamics.SecondOrderSystem.undamped_modes` solves them once per model
    (one dense/sparse policy, :mod:`wingopt.dynamics.modes`) and serves every later request.
    """
    return model.system.undamped_modes(int(min(count, model.n)))


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
    # One mode solve for the initial gain (weight_modes + 40), the weight and the shift space.
    shift_modes = int(kw.pop("shift_modes", 60))
    _, Phi = _modes(model, max(int(weight_modes) + 40, shift_modes))
    K0 = reduced_initial_gain(model, r, alpha, beta, weight_modes)
    t_init = time.perf_counter() - t0
    C = plate_weight(model, alpha, beta, weight_modes)
    res = care_nk_adi(
        model.mass,
        model.damping,
        model.stiffness,
        model.actuation,
        C,
        r * np.eye(model.n_inputs),
        K0,
        shift_basis=Phi[:, : min(shift_modes, model.n - 1)],
        **kw,
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
    kb = model.system.static_solve(K[:, :n].T)
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
