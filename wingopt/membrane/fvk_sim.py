"""Time response of the Föppl–von Kármán membrane by an exponential integrator.

The FvK force splits into the prestress part and a remainder, ``F(z) = K_T0 z + N(z)``. In the
separable modes of :mod:`wingopt.membrane.berger` (``z = V q``) the prestress part and the damping
are diagonal, so each mode is propagated exactly (augmented matrix exponential) with the forcing
``V^T p - V^T N(z)`` linear over the step (exponential-trapezoidal rule): the time error is
confined to the deflection-induced tension, and a vanishing load gives the linear model's exact
zero-order hold. The implicit step is solved by a quasi-Newton iteration whose matrix is the
Berger model's exact Jacobian (diagonal plus rank 2, solved by Woodbury), i.e. the uniform-tension
part of the FvK tangent; no large matrix is factorised. The in-plane equilibrium is solved exactly
at every iterate (one solve with the constant in-plane stiffness).

:func:`wingopt.membrane.nonlinear.integrate` (generalised-alpha with the full coupled tangent)
integrates the same equations by an independent route; the two agree as the steps shrink (tested).
"""

from __future__ import annotations

import logging

import numpy as np

from wingopt.errors import InputError, SolverError
from wingopt.membrane.berger import BergerMembrane
from wingopt.membrane.berger_sim import _load_samples, _step_matrices
from wingopt.membrane.fvk import FvKMembrane
from wingopt.membrane.nonlinear import AlphaResult

__all__ = ["simulate_fvk"]

log = logging.getLogger(__name__)


def simulate_fvk(
    model: FvKMembrane,
    load,
    t_end: float,
    dt: float = 1.0e-3,
    z0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    substeps: int = 2,
    tol: float = 1e-10,
    max_iter: int = 60,
) -> AlphaResult:
    """Integrate the FvK membrane (quasi-static in-plane equilibrium) under load coefficients ``f``.

    Parameters
    ----------
    model : FvKMembrane
    load : ndarray ``(n,)`` or callable ``t -> (n,)``
        Load coefficients in the deflection basis (force ``p = M f``), linear between step times.
    t_end, dt : float
        Duration and output sample period (s).
    substeps : int
        Steps per sample (time error in the docs: 2 at 1 ms is below 0.1 % of the sensor peak).
    tol : float
        Iteration stops when ``max|dq| <= tol * max|q|``.

    Returns
    -------
    AlphaResult
        Times, deflection and velocity coefficients at the samples, iteration count
        (``factorizations`` is 0: nothing is factorised per step).
    """
    if not (np.isfinite(t_end) and t_end > 0 and np.isfinite(dt) and dt > 0):
        raise InputError(f"t_end = {t_end!r}, dt = {dt!r}: expected positive durations (s)")
    if not (isinstance(substeps, (int, np.integer)) and substeps >= 1):
        raise InputError(f"substeps = {substeps!r}: expected an integer >= 1")
    berger = BergerMembrane(model.linear, model.params)
    modes, par, mat = berger.modes, model.params, model.problem.material
    lx, ly = modes.lam_x, modes.lam_y
    C, nu, A = berger.C, berger.nu, berger.area
    tx0, ty0 = berger.prestress
    k = tx0 * lx + ty0 * ly
    c = par.viscous_scale * mat.viscous + par.kelvin_voigt_scale * mat.kelvin_voigt * k
    samples = int(round(t_end / dt))
    h = dt / substeps
    E, _, _ = _step_matrices(berger.rho_h, k, c, h, False)
    Phi, G0, G1 = E[:, :2, :2], E[:, :2, 2] - E[:, :2, 3], E[:, :2, 3]
    Binv = np.linalg.inv((C / A) * np.array([[1.0, nu], [nu, 1.0]]))
    times = np.arange(samples * substeps + 1) * h
    P = _load_samples(berger, load, times)
    q = np.zeros(model.n) if z0 is None else modes.to_modal(np.asarray(z0, float))
    v = np.zeros(model.n) if v0 is None else modes.to_modal(np.asarray(v0, float))

    def remainder(q):
        """Modal ``V^T N(Vq)``: the FvK force less its prestress part."""
        return modes.to_modal_force(model.force(modes.to_field(q))) - k * q

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
            prev = np.inf
            for _it in range(max_iter):
                N1 = remainder(q1)
                r = q1 - base + G1[:, 0] * N1
                # Berger Jacobian of the remainder at q1: diag(dTx lx + dTy ly) + U B U^T.
                sx, sy = np.sum(lx * q1 * q1) / (2 * A), np.sum(ly * q1 * q1) / (2 * A)
                delta = 1.0 + G1[:, 0] * (C * (sx + nu * sy) * lx + C * (sy + nu * sx) * ly)
                U = np.column_stack([lx * q1, ly * q1])
                Pm = (G1[:, 0] / delta)[:, None] * U
                y = r / delta
                dq = -(y - Pm @ np.linalg.solve(Binv + U.T @ Pm, U.T @ y))
                q1 = q1 + dq
                iters += 1
                size = np.max(np.abs(dq))
                if size <= tol * max(np.max(np.abs(q1)), 1e-300):
                    break
                if size > prev:
                    raise SolverError("FvK step", f"diverges at t = {times[step]:.4g} s", "reduce dt or add substeps")
                prev = size
            else:
                raise SolverError(
                    "FvK step", f"no convergence in {max_iter} iterations at t = {times[step]:.4g} s", "add substeps"
                )
            N1 = remainder(q1)
            v = Phi[:, 1, 0] * q + Phi[:, 1, 1] * v + G0[:, 1] * f0 + G1[:, 1] * (P[step + 1] - N1)
            q, N0, Nprev = q1, N1, N0
            step += 1
        Q[s + 1], Vq[s + 1] = q, v
    log.debug("FvK exponential: %d samples x %d substeps, %d iterations", samples, substeps, iters)
    return AlphaResult(times[::substeps], modes.to_field(Q.T).T, modes.to_field(Vq.T).T, iters, 0)
