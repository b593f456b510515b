"""The time-resolved full-field mode: every frame's load, with the membrane's inertia in the balance.

About the steady fit (its prestrains, load prior and tangent ``K_t`` at the mean deflection), each
frame ``k`` with fit ``ẑ_k`` gives ``y_k = W_k - B ẑ_k + B K_t^-1 (F(ẑ_k) + r_k) = A c_k + noise``
(:mod:`.system`) with the frame's own internal force ``F(ẑ_k)`` (exact, not linearised) and the
inertia and damping forces ``r_k = rho h M z̈_k + D ż_k`` from the fitted frames' time derivatives
(spectral: :func:`_derivatives`; their noise is negligible for the smooth shapes a pressure excites). The
prior of ``c_k`` is centred on the steady load with the steady prior's spread; a frame's missing
points are rows left out. Each frame costs one small solve: 450 frames of 800 points in a
second or two.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wingopt.estimation.fullfield.data import FieldData
from wingopt.estimation.fullfield.steady import SteadyFit

__all__ = ["FrameLoads", "frame_loads"]


@dataclass(frozen=True, eq=False)
class FrameLoads:
    """Per-frame estimates: times (K,), shape coefficients (K, m), deflections (K, n), lift and band (K,)."""

    t: np.ndarray
    c: np.ndarray
    z: np.ndarray
    lift: np.ndarray
    lift_std: np.ndarray
    chi2_per_datum: np.ndarray


def _derivatives(t: np.ndarray, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations of the frame fits ``Z`` (K, n) at times ``t``, spectrally.

    The histories are put on a uniform grid (a left-out frame interpolated), their linear trend is
    removed and they are extended odd-symmetrically (no jump at the ends), then differentiated in
    Fourier space: exact below the Nyquist frequency, where a 300 Hz record's membrane response
    lies (f11 ≈ 80-100 Hz). Central differences lose 26 % of the acceleration at 90 Hz: on a
    buffeting record the lift history's error was 6x larger with them (docs/dic.md).
    """
    if t.size < 4:
        return np.zeros_like(Z), np.zeros_like(Z)
    dt = float(np.median(np.diff(t)))
    n = int(round((t[-1] - t[0]) / dt)) + 1
    grid = t[0] + dt * np.arange(n)
    k = np.clip(np.round((t - t[0]) / dt).astype(int), 0, n - 1)
    U = Z if n == t.size else np.stack([np.interp(grid, t, Z[:, j]) for j in range(Z.shape[1])], axis=1)
    slope = (U[-1] - U[0]) / (grid[-1] - grid[0])
    D = U - U[0] - np.outer(grid - grid[0], slope)
    E = np.concatenate([D, -D[::-1]], axis=0)
    iw = 2j * np.pi * np.fft.rfftfreq(2 * n, dt)
    F = np.fft.rfft(E, axis=0)
    v = np.fft.irfft(iw[:, None] * F, n=2 * n, axis=0)[:n] + slope
    a = np.fft.irfft((iw**2)[:, None] * F, n=2 * n, axis=0)[:n]
    return v[k], a[k]


def frame_loads(data: FieldData, fit: SteadyFit, inertia: bool = True) -> FrameLoads:
    """Each used frame's load about the steady fit ``fit`` (module docstring)."""
    system, shapes = fit.system, fit.shapes
    e0 = fit.prestrain
    A, _, solve, S, _, fvk = system.at(e0)
    fr = data.frames
    idx = np.flatnonzero(data.used)
    t, Z = fr.t[idx], data.fit.coef[idx]
    forces = np.stack([fvk.force(z) for z in Z], axis=1)  # (n, K)
    if inertia:
        zd, zdd = _derivatives(t, Z)
        forces = forces + fvk.mass @ zdd.T + fvk.damping @ zd.T
    s = solve(forces)  # (n, K)
    B = data.basis
    Y = np.where(fr.valid[idx], fr.w[idx], 0.0) - Z @ B.T + (B @ s).T  # (K, P)
    w2 = 1.0 / data.sigma**2
    AtA = A.T @ A * w2
    P0 = np.diag(1.0 / shapes.prior_std**2)
    c0 = fit.post.c
    g = shapes.lift_row
    K, m = idx.size, c0.size
    C, chi2 = np.empty((K, m)), np.empty(K)
    lift_var = np.empty(K)
    for j, k in enumerate(idx):
        ok = fr.valid[k]
        bad = ~ok
        G = AtA - (A[bad].T @ A[bad]) * w2 if bad.any() else AtA
        H = G + P0
        r0 = np.where(ok, Y[j] - A @ c0, 0.0)
        c = c0 + np.linalg.solve(H, A.T @ r0 * w2)
        r = np.where(ok, Y[j] - A @ c, 0.0)
        eff = float(np.trace(np.linalg.solve(H, G)))
        chi2[j] = float(r @ r) * w2 / max(ok.sum() - eff, 1.0)
        C[j] = c
        lift_var[j] = max(1.0, chi2[j]) * float(g @ np.linalg.solve(H, g))
    lift = C @ g
    z = Z - s.T + C @ S.T
    # the prestrains' part scales with the load (F and the load are affine in the prestress)
    e0_part = (fit.lift_grad @ fit.theta_cov @ fit.lift_grad) * (lift / fit.lift) ** 2
    return FrameLoads(t, C, z, lift, np.sqrt(lift_var + e0_part), chi2)
