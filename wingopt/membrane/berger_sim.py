"""Time response of the Berger membrane, and its forward sensitivities to the parameters.

In the separable modes (``z = V q``, see :mod:`wingopt.membrane.berger`) every mode is a damped
oscillator ``rho h q'' + c_k q' + k_k q = f_k``, ``k_k = Tx0 lx_k + Ty0 ly_k``,
``c_k = s_v gamma + s_kv eta k_k``, driven by the load and by the deflection-induced tension
``f = V^T p - N(q)``, ``N(q) = (dTx(q) lx + dTy(q) ly) q``. The oscillators are propagated
exactly (augmented matrix exponential) with the forcing linear over each step
(exponential-trapezoidal rule), implicit in ``N`` and solved by Newton with the exact
diagonal-plus-rank-2 Jacobian (Woodbury). Without the stretch term this *is* the linear model's
exact zero-order hold (constant load), so the time error is confined to the nonlinear part.

Forward sensitivities ``dz/dtheta`` for ``theta = (eps0_x, eps0_y, viscous_scale,
kelvin_voigt_scale)`` and, optionally, constant load directions are propagated with the same
Jacobian; the derivatives of the step matrices come from Fréchet derivatives of the exponential.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from wingopt.errors import InputError, SolverError
from wingopt.membrane.berger import BergerMembrane

__all__ = ["BergerTrajectory", "simulate_berger"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class BergerTrajectory:
    """Sampled Berger response.

    Attributes
    ----------
    t : (N+1,) times; z, zdot : (N+1, n) deflection and velocity coefficients
    outputs : (N+1, p) sensor outputs ``z^T C_i z``; tensions : (N+1, 2) ``Tx, Ty`` (N/m)
    dz, doutputs : (N+1, n, k) and (N+1, p, k) sensitivities, or ``None``
    sensitivity_names : names of the k sensitivity columns
    """

    t: np.ndarray
    z: np.ndarray
    zdot: np.ndarray
    outputs: np.ndarray
    tensions: np.ndarray
    dz: np.ndarray | None = None
    doutputs: np.ndarray | None = None
    sensitivity_names: tuple[str, ...] = ()


@dataclass(eq=False)
class _Sensitivity:
    """Forward sensitivities through the exponential-trapezoidal step (shared by the Berger and
    cubic modal models): step-matrix derivatives, constant forcing derivatives, initial values."""

    dPhi: np.ndarray  # (n, 2, 2, k)
    dG0: np.ndarray  # (n, 2, k)
    dG1: np.ndarray
    dP: np.ndarray  # (n, k): d(modal load)/d theta
    Sq0: np.ndarray
    Sv0: np.ndarray
    names: tuple[str, ...]

    @classmethod
    def setup(cls, model, k, dEk, dEc, load_directions=None, state_directions=None) -> _Sensitivity:
        par, mat, modes = model.params, model.problem.material, model.modes
        lx, ly, C, nu = modes.lam_x, modes.lam_y, model.C, model.nu
        dk = np.column_stack([C * (lx + nu * ly), C * (nu * lx + ly), np.zeros_like(k), np.zeros_like(k)])
        kv = par.kelvin_voigt_scale * mat.kelvin_voigt
        zero = np.zeros_like(k)
        dc = kv * dk + np.column_stack([zero, zero, np.full_like(k, mat.viscous), mat.kelvin_voigt * k])
        dE = dEk[:, :, :, None] * dk[:, None, None, :] + dEc[:, :, :, None] * dc[:, None, None, :]  # (n, 4, 4, 4)
        n = model.n
        blocks, names = [np.zeros((n, 4))], list(par.NAMES)
        s_q, s_v = [np.zeros((n, 4))], [np.zeros((n, 4))]
        if load_directions is not None:
            L = np.asarray(load_directions, dtype=float).reshape(n, -1)
            blocks.append(modes.to_modal_force(model.gram @ L))
            names += [f"load_{j}" for j in range(L.shape[1])]
            s_q.append(np.zeros_like(L))
            s_v.append(np.zeros_like(L))
        if state_directions is not None:
            dz0, dv0 = (np.asarray(d, dtype=float).reshape(n, -1) for d in state_directions)
            names += [f"z0_{j}" for j in range(dz0.shape[1])] + [f"v0_{j}" for j in range(dv0.shape[1])]
            blocks.append(np.zeros((n, dz0.shape[1] + dv0.shape[1])))
            s_q += [modes.to_modal(dz0) if dz0.shape[1] else dz0, np.zeros_like(dv0)]
            s_v += [np.zeros_like(dz0), modes.to_modal(dv0) if dv0.shape[1] else dv0]
        dP = np.hstack(blocks)
        extra = dP.shape[1] - 4
        dE = np.concatenate([dE, np.zeros(dE.shape[:3] + (extra,))], axis=3)
        return cls(
            dE[:, :2, :2], dE[:, :2, 2] - dE[:, :2, 3], dE[:, :2, 3], dP, np.hstack(s_q), np.hstack(s_v), tuple(names)
        )

    def step(self, q, v, f0, f1, Sq, Sv, Phi, G0, G1, jn0, jn1, solve1):
        """One step of ``S = d(q, v)/d theta``; ``jn*`` apply the nonlinear force Jacobian at the
        old / new state, ``solve1`` solves ``(I + G1_q J_N(q1)) X = rhs``."""
        dF0 = self.dP - jn0(Sq)
        terms = lambda row, dF1: (  # noqa: E731
            self.dPhi[:, row, 0] * q[:, None]
            + self.dPhi[:, row, 1] * v[:, None]
            + Phi[:, row, 0, None] * Sq
            + Phi[:, row, 1, None] * Sv
            + self.dG0[:, row] * f0[:, None]
            + G0[:, row, None] * dF0
            + self.dG1[:, row] * f1[:, None]
            + G1[:, row, None] * dF1
        )
        Sq1 = solve1(terms(0, self.dP))
        Sv1 = terms(1, self.dP - jn1(Sq1))
        return Sq1, Sv1


def _sensitivity_outputs(model, Z: np.ndarray, SQ: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``dZ (N+1, n, k)`` and sensor sensitivities ``2 z^T C_i dz`` ``(N+1, p, k)`` from modal ``SQ``."""
    nt, n, nk = SQ.shape
    dZ = model.modes.to_field(SQ.transpose(1, 0, 2).reshape(n, -1)).reshape(n, nt, nk).transpose(1, 0, 2)
    flat = dZ.transpose(1, 0, 2).reshape(n, -1)
    sensors = model.linear.sensors
    dout = np.stack(
        [2.0 * np.einsum("tn,ntk->tk", Z, (Cm @ flat).reshape(n, nt, nk)) for Cm in sensors.matrices], axis=1
    )
    return dZ, dout


def _step_matrices(m: float, k: np.ndarray, c: np.ndarray, h: float, derivatives: bool):
    """Per mode ``E = expm([[A h, b h, 0], [0, 0, 1], [0, 0, 0]])`` and ``dE/dk, dE/dc``."""
    n = k.size
    Ma = np.zeros((n, 4, 4))
    Ma[:, 0, 1] = h
    Ma[:, 1, 0] = -k * h / m
    Ma[:, 1, 1] = -c * h / m
    Ma[:, 1, 2] = h / m
    Ma[:, 2, 3] = 1.0
    if not derivatives:
        return sla.expm(Ma), None, None
    out = []
    for row, col in ((1, 0), (1, 1)):  # d/dk, d/dc: the entries -k h/m and -c h/m
        big = np.zeros((n, 8, 8))
        big[:, :4, :4] = Ma
        big[:, 4:, 4:] = Ma
        big[:, row, 4 + col] = -h / m
        out.append(sla.expm(big))
    return out[0][:, :4, :4], out[0][:, :4, 4:], out[1][:, :4, 4:]


def _load_samples(model: BergerMembrane, load, times: np.ndarray) -> np.ndarray:
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


def simulate_berger(
    model: BergerMembrane,
    load,
    t_end: float,
    dt: float = 1.0e-3,
    z0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    substeps: int = 1,
    sensitivities: bool = False,
    load_directions: np.ndarray | None = None,
    state_directions: tuple[np.ndarray, np.ndarray] | None = None,
    nonlinear: bool = True,
    tol: float = 1e-12,
    max_iter: int = 30,
) -> BergerTrajectory:
    """Integrate the Berger membrane from ``(z0, v0)`` under load coefficients ``f`` (``p = M f``).

    Parameters
    ----------
    load : ndarray ``(n,)`` or callable ``t -> (n,)``
        Load coefficients in the deflection basis, linear between the (sub)step times.
    t_end, dt : float
        Duration and output sample period (s).
    substeps : int
        Steps per sample (1 is enough at 1 ms for the seed's loads; measured in the docs).
    sensitivities : bool
        Also propagate ``dz/dtheta`` for the four :class:`MembraneParameters` and for each column
        of ``load_directions`` (``(n, m)`` load coefficients whose weights are constant).
    state_directions : (dz0, dv0), optional
        Also sensitivities to the initial state along the columns of ``dz0`` (``(n, r)``
        deflection coefficients, then ``dv0``, ``(n, s)`` velocity coefficients): e.g. the
        identity for the full state of a short estimation window, or a reduced basis.
    nonlinear : bool
        ``False`` drops the stretch term: the linear model with tensions ``Tx0, Ty0`` (for a
        constant load the linear model's exact zero-order hold).
    """
    if not (np.isfinite(t_end) and t_end > 0 and np.isfinite(dt) and dt > 0):
        raise InputError(f"t_end = {t_end!r}, dt = {dt!r}: expected positive durations (s)")
    if not (isinstance(substeps, (int, np.integer)) and substeps >= 1):
        raise InputError(f"substeps = {substeps!r}: expected an integer >= 1")
    samples = int(round(t_end / dt))
    h = dt / substeps
    modes, par, mat = model.modes, model.params, model.problem.material
    lx, ly = modes.lam_x, modes.lam_y
    C, nu, A, m = model.C, model.nu, model.area, model.rho_h
    tx0, ty0 = model.prestress
    k = tx0 * lx + ty0 * ly
    c = par.viscous_scale * mat.viscous + par.kelvin_voigt_scale * mat.kelvin_voigt * k
    E, dEk, dEc = _step_matrices(m, k, c, h, sensitivities)
    Phi = E[:, :2, :2]
    G0, G1 = E[:, :2, 2] - E[:, :2, 3], E[:, :2, 3]
    kappa = model.stretch_gain
    B = (kappa * C / A) * np.array([[1.0, nu], [nu, 1.0]])
    Binv = np.linalg.inv(B)
    times = np.arange(samples * substeps + 1) * h
    P = _load_samples(model, load, times)
    q = np.zeros(model.n) if z0 is None else modes.to_modal(np.asarray(z0, float))
    v = np.zeros(model.n) if v0 is None else modes.to_modal(np.asarray(v0, float))

    def stretch_force(q):
        if not nonlinear:
            return np.zeros_like(q), np.zeros_like(q), np.zeros((q.size, 2))
        sx, sy = np.sum(lx * q * q) / (2 * A), np.sum(ly * q * q) / (2 * A)
        dtx, dty = kappa * C * (sx + nu * sy), kappa * C * (sy + nu * sx)
        return (dtx * lx + dty * ly) * q, dtx * lx + dty * ly, np.column_stack([lx * q, ly * q])

    if sensitivities:
        sens = _Sensitivity.setup(model, k, dEk, dEc, load_directions, state_directions)
        Sq, Sv = sens.Sq0, sens.Sv0
        SQ = np.empty((samples + 1,) + Sq.shape)
        SQ[0] = Sq
    Q, Vq = np.empty((samples + 1, model.n)), np.empty((samples + 1, model.n))
    Q[0], Vq[0] = q, v
    N0, diag0, U0 = stretch_force(q)
    iters = 0
    step = 0
    for s in range(samples):
        for _ in range(substeps):
            f0 = P[step] - N0
            base_q = Phi[:, 0, 0] * q + Phi[:, 0, 1] * v + G0[:, 0] * f0 + G1[:, 0] * P[step + 1]
            q1 = base_q - G1[:, 0] * N0
            for _it in range(max_iter):
                N1, diag1, U1 = stretch_force(q1)
                r = q1 - base_q + G1[:, 0] * N1
                delta = 1.0 + G1[:, 0] * diag1
                Pm = (G1[:, 0] / delta)[:, None] * U1
                cap = Binv + U1.T @ Pm
                y = r / delta
                dq = -(y - Pm @ np.linalg.solve(cap, U1.T @ y))
                q1 = q1 + dq
                iters += 1
                if np.max(np.abs(dq)) <= tol * max(np.max(np.abs(q1)), 1e-300):
                    break
            else:
                raise SolverError("Berger step", f"Newton did not converge at t = {times[step]:.4g} s", "add substeps")
            N1, diag1, U1 = stretch_force(q1)
            f1 = P[step + 1] - N1
            v1 = Phi[:, 1, 0] * q + Phi[:, 1, 1] * v + G0[:, 1] * f0 + G1[:, 1] * f1
            if sensitivities:

                def jn0(S, d=diag0, U=U0):
                    return d[:, None] * S + U @ (B @ (U.T @ S))

                def jn1(S, d=diag1, U=U1):
                    return d[:, None] * S + U @ (B @ (U.T @ S))

                def solve1(rhs, d=diag1, U=U1):
                    delta = 1.0 + G1[:, 0] * d
                    Pm = (G1[:, 0] / delta)[:, None] * U
                    y = rhs / delta[:, None]
                    return y - Pm @ np.linalg.solve(Binv + U.T @ Pm, U.T @ y)

                Sq, Sv = sens.step(q, v, f0, f1, Sq, Sv, Phi, G0, G1, jn0, jn1, solve1)
            q, v, N0, diag0, U0 = q1, v1, N1, diag1, U1
            step += 1
        Q[s + 1], Vq[s + 1] = q, v
        if sensitivities:
            SQ[s + 1] = Sq
    log.debug("Berger: %d samples x %d substeps, %d Newton iterations", samples, substeps, iters)
    Z, Zd = modes.to_field(Q.T).T, modes.to_field(Vq.T).T
    sx = np.einsum("tk,k,tk->t", Q, lx, Q) / (2 * A)
    sy = np.einsum("tk,k,tk->t", Q, ly, Q) / (2 * A)
    sx, sy = (kappa * sx, kappa * sy) if nonlinear else (0 * sx, 0 * sy)
    T = np.column_stack(
        [C * (par.eps0_x + sx + nu * (par.eps0_y + sy)), C * (par.eps0_y + sy + nu * (par.eps0_x + sx))]
    )
    sensors = model.linear.sensors
    out = sensors.outputs(Z)
    if not sensitivities:
        return BergerTrajectory(times[::substeps], Z, Zd, out, T)
    dZ, dout = _sensitivity_outputs(model, Z, SQ)
    return BergerTrajectory(times[::substeps], Z, Zd, out, T, dZ, dout, sens.names)
