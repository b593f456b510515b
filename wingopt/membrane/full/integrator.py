"""Time response of the full-order membranes (linear, Berger, FvK) by one exponential integrator.

The internal force splits into the prestress part and a remainder, ``F(z) = K_T0 z + N(z)``
(``N = 0`` for the linear membrane; Berger's uniform stretch tension, or the Föppl–von Kármán
force with the in-plane equilibrium solved exactly at every iterate). In the separable modes of
:class:`~wingopt.membrane.full.berger.SeparableModes` (``z = V q``) the prestress part and the
damping are diagonal, so each mode is propagated exactly (augmented matrix exponential) with the
forcing ``V^T p - V^T N(z)`` linear over the step (exponential-trapezoidal rule): the time error is
confined to the deflection-induced tension, and ``N = 0`` is the linear model's exact zero-order
hold (constant load). The implicit step is solved by Newton whose matrix is the Berger model's
exact Jacobian (diagonal plus rank 2, solved by Woodbury): exact Newton for Berger, a quasi-Newton
for FvK (the uniform-tension part of its tangent); no large matrix is factorised.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from wingopt.errors import InputError, SolverError

__all__ = ["FullRecord", "integrate"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class FullRecord:
    """Sampled full-order response: times ``(N+1,)``, deflection and velocity coefficients ``(N+1, n)``,
    and the Newton iterations spent."""

    t: np.ndarray
    z: np.ndarray
    zdot: np.ndarray
    iterations: int


def step_matrices(m: float, k: np.ndarray, c: np.ndarray, h: float) -> np.ndarray:
    """Per mode ``E = expm([[A h, b h, 0], [0, 0, 1], [0, 0, 0]])`` of ``m q'' + c q' + k q = f(t)``
    with ``f`` linear over the step (``(n, 4, 4)``)."""
    n = k.size
    Ma = np.zeros((n, 4, 4))
    Ma[:, 0, 1] = h
    Ma[:, 1, 0] = -k * h / m
    Ma[:, 1, 1] = -c * h / m
    Ma[:, 1, 2] = h / m
    Ma[:, 2, 3] = 1.0
    return sla.expm(Ma)


def _load_samples(model, load, times: np.ndarray) -> np.ndarray:
    """Modal forces ``V^T M f(t)`` at ``times`` from coefficients ``(n,)``, ``(len(times), n)`` or ``t -> (n,)``."""
    n = model.n
    if callable(load):
        F = np.stack([np.asarray(load(t), dtype=float) for t in times])
    else:
        F = np.asarray(load, dtype=float)
        if F.shape == (n,):
            F = np.broadcast_to(F, (times.size, n))
    if F.shape != (times.size, n):
        raise InputError(f"load: shape {F.shape}, expected ({n},), ({times.size}, {n}) or a callable t -> ({n},)")
    return model.modes.to_modal_force(model.gram @ F.T).T


def integrate(
    model,
    load,
    t_end: float,
    dt: float = 1.0e-3,
    z0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    substeps: int = 2,
    nonlinear: bool = True,
    tol: float = 1e-10,
    max_iter: int = 60,
) -> FullRecord:
    """Integrate a full-order membrane from ``(z0, v0)`` (default rest) under load coefficients ``f``.

    Parameters
    ----------
    model : BergerMembrane or FvKMembrane
        Provides ``modes``, ``params``, ``prestress``, ``remainder(q)`` (modal ``V^T N(V q)``),
        ``stretch_gain`` and the material constants ``C``, ``nu``, ``area``, ``rho_h``.
    load : ndarray ``(n,)`` or callable ``t -> (n,)``
        Load coefficients in the deflection basis (force ``p = M f``), linear between step times.
    t_end, dt : float
        Duration and output sample period (s).
    substeps : int
        Steps per sample (FvK: 2 at 1 ms is below 0.1 % of the sensor peak, docs).
    nonlinear : bool
        ``False``: the linear membrane at the model's prestress (exact for a constant load).
    tol : float
        Newton stops when ``max|dq| <= tol * max|q|``.
    """
    if not (np.isfinite(t_end) and t_end > 0 and np.isfinite(dt) and dt > 0):
        raise InputError(f"t_end = {t_end!r}, dt = {dt!r}: expected positive durations (s)")
    if not (isinstance(substeps, (int, np.integer)) and substeps >= 1):
        raise InputError(f"substeps = {substeps!r}: expected an integer >= 1")
    modes, par, mat = model.modes, model.params, model.problem.material
    lx, ly = modes.lam_x, modes.lam_y
    C, nu, A, kappa = model.C, model.nu, model.area, model.stretch_gain
    tx0, ty0 = model.prestress
    k = tx0 * lx + ty0 * ly
    c = par.viscous_scale * mat.viscous + par.kelvin_voigt_scale * mat.kelvin_voigt * k
    samples = int(round(t_end / dt))
    h = dt / substeps
    E = step_matrices(model.rho_h, k, c, h)
    Phi, G0, G1 = E[:, :2, :2], E[:, :2, 2] - E[:, :2, 3], E[:, :2, 3]
    jac = (lx, ly, kappa, C, nu, A, np.linalg.inv((kappa * C / A) * np.array([[1.0, nu], [nu, 1.0]])))
    times = np.arange(samples * substeps + 1) * h
    P = _load_samples(model, load, times)
    q = np.zeros(model.n) if z0 is None else modes.to_modal(np.asarray(z0, float))
    v = np.zeros(model.n) if v0 is None else modes.to_modal(np.asarray(v0, float))
    remainder = model.remainder if nonlinear else np.zeros_like
    N0 = remainder(q)
    Nprev = N0
    Q, Vq = np.empty((samples + 1, model.n)), np.empty((samples + 1, model.n))
    Q[0], Vq[0] = q, v
    iters, step = 0, 0
    for s in range(samples):
        for _ in range(substeps):
            f0 = P[step] - N0
            base = Phi[:, 0, 0] * q + Phi[:, 0, 1] * v + G0[:, 0] * f0 + G1[:, 0] * P[step + 1]
            q1 = base - G1[:, 0] * (2 * N0 - Nprev)  # remainder extrapolated linearly in time
            if nonlinear:
                q1, n_it = _newton(q1, base, remainder, G1[:, 0], jac, tol, max_iter, times[step])
                iters += n_it
            N1 = remainder(q1)
            v = Phi[:, 1, 0] * q + Phi[:, 1, 1] * v + G0[:, 1] * f0 + G1[:, 1] * (P[step + 1] - N1)
            q, N0, Nprev = q1, N1, N0
            step += 1
        Q[s + 1], Vq[s + 1] = q, v
    log.debug("full-order %s: %d samples x %d substeps, %d iterations", type(model).__name__, samples, substeps, iters)
    return FullRecord(times[::substeps], modes.to_field(Q.T).T, modes.to_field(Vq.T).T, iters)


def _newton(q1, base, remainder, g1, jac: tuple, tol: float, max_iter: int, t: float) -> tuple[np.ndarray, int]:
    """Solve one implicit step ``q1 - base + g1 N(q1) = 0`` by Newton from ``q1``: the step and its iterations.

    ``jac``: ``(lx, ly, kappa, C, nu, A, Binv)``, the Berger Jacobian's data (the remainder's Jacobian
    at ``q1`` is ``diag(dTx lx + dTy ly) + U B U^T``, inverted by Woodbury). ``t``: the step's time (errors).
    """
    lx, ly, kappa, C, nu, A, Binv = jac
    prev, iters = np.inf, 0
    for _it in range(max_iter):
        N1 = remainder(q1)
        r = q1 - base + g1 * N1
        sx, sy = kappa * np.sum(lx * q1 * q1) / (2 * A), kappa * np.sum(ly * q1 * q1) / (2 * A)
        delta = 1.0 + g1 * (C * (sx + nu * sy) * lx + C * (sy + nu * sx) * ly)
        U = np.column_stack([lx * q1, ly * q1])
        Pm = (g1 / delta)[:, None] * U
        y = r / delta
        dq = -(y - Pm @ np.linalg.solve(Binv + U.T @ Pm, U.T @ y))
        q1 = q1 + dq
        iters += 1
        size = np.max(np.abs(dq))
        if size <= tol * max(np.max(np.abs(q1)), 1e-300):
            return q1, iters
        if size > prev:
            raise SolverError("membrane step", f"diverges at t = {t:.4g} s", "reduce dt or add substeps")
        prev = size
    raise SolverError("membrane step", f"no convergence in {max_iter} iterations at t = {t:.4g} s", "add substeps")
