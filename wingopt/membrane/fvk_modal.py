"""A reduced FvK membrane with the exact cubic stiffness on the lowest modes.

The FvK in-plane problem is linear, so ``u, v`` are quadratic in ``w`` and the out-of-plane force
is exactly cubic: ``F(z) = K_T0 z + N(z)``, ``N`` homogeneous of degree 3. On the ``r`` lowest
separable modes ``Phi`` (see :mod:`wingopt.membrane.berger`; M-orthonormal, ``K_T0`` and ``D``
diagonal) the Galerkin projection ``Phi^T N(Phi a) = B(a, a, a)`` is a symmetric cubic form whose
tensor is computed once from ``r^2`` in-plane solves. The model keeps *all* modes: the ``r``
lowest carry the exact cubic stiffness, the others respond linearly (prestress tension only). As
``r -> n`` it is the FvK model exactly; the truncation error is measured in the docs.

Dynamics as in :mod:`wingopt.membrane.berger_sim` (exact exponential for the linear part, the
nonlinear force trapezoidal), Newton with the exact dense ``r x r`` Jacobian ``3 B(., a, a)``.
"""

from __future__ import annotations

import logging

import numpy as np

from wingopt.errors import InputError, SolverError
from wingopt.membrane.berger import BergerMembrane
from wingopt.membrane.berger_sim import (
    BergerTrajectory,
    _load_samples,
    _Sensitivity,
    _sensitivity_outputs,
    _step_matrices,
)
from wingopt.membrane.fvk import FvKMembrane

__all__ = ["CubicModalMembrane", "cubic_tensor"]

log = logging.getLogger(__name__)


def cubic_tensor(fvk: FvKMembrane, shapes: np.ndarray) -> np.ndarray:
    """Symmetrised ``B[i, (j, k, l)]`` ``(r, r^3)`` with ``shapes^T N(shapes a) = B (a⊗a⊗a)``.

    ``shapes`` ``(n, r)``: coefficient vectors of any ``r`` deflection shapes of ``fvk``'s space
    (``r^2 / 2`` in-plane solves). The tensor does not depend on the prestrains or the damping.
    """
    r = shapes.shape[1]
    o, C, nu, W = fvk.ops, fvk.C, fvk.nu, fvk.ops.weights
    G = 0.5 * C * (1 - nu)
    gx, gy = np.array([o.gradient(shapes[:, j]) for j in range(r)]).transpose(1, 0, 2)  # (r, nq) each
    lu = fvk._inplane[1]
    n = fvk.n
    # Quadratic strains of each ordered pair (j, k): w = phi_j + phi_k contributes a_j a_k (...).
    ex = 0.5 * gx[:, None, :] * gx[None, :, :]
    ey = 0.5 * gy[:, None, :] * gy[None, :, :]
    gg = 0.5 * (gx[:, None, :] * gy[None, :, :] + gy[:, None, :] * gx[None, :, :])
    S = np.empty((3, r, r, W.size))
    for j in range(r):
        for k in range(j, r):
            nx, ny, nxy = C * (ex[j, k] + nu * ey[j, k]), C * (ey[j, k] + nu * ex[j, k]), G * gg[j, k]
            rhs = np.concatenate([o.divergence(W * nx, W * nxy), o.divergence(W * nxy, W * ny)])
            uv = -lu.solve(rhs)
            ux, uy = o.gradient(uv[:n])
            vx, vy = o.gradient(uv[n:])
            exj, eyj, gj = ex[j, k] + ux, ey[j, k] + vy, gg[j, k] + uy + vx
            S[:, j, k] = S[:, k, j] = (C * (exj + nu * eyj), C * (eyj + nu * exj), G * gj)
    # B[j, k, i, l] = ∫ Sx_jk phi_i,x phi_l,x + Sy_jk phi_i,y phi_l,y + Sxy_jk (phi_i,x phi_l,y + phi_i,y phi_l,x)
    Sw = S.reshape(3, r * r, -1) * W
    B = Sw[0] @ np.einsum("iq,lq->qil", gx, gx).reshape(W.size, r * r)
    B += Sw[1] @ np.einsum("iq,lq->qil", gy, gy).reshape(W.size, r * r)
    B += Sw[2] @ (np.einsum("iq,lq->qil", gx, gy) + np.einsum("iq,lq->qil", gy, gx)).reshape(W.size, r * r)
    B = B.reshape(r, r, r, r).transpose(2, 0, 1, 3)  # (i, j, k, l)
    perms = ((1, 2, 3), (1, 3, 2), (2, 1, 3), (2, 3, 1), (3, 1, 2), (3, 2, 1))
    B = sum(B.transpose((0,) + p) for p in perms) / 6.0
    return B.reshape(r, r**3)


class CubicModalMembrane:
    """FvK membrane with the exact cubic stiffness on its ``modes`` lowest separable modes.

    Parameters
    ----------
    fvk : FvKMembrane
        The full model (mesh, material, prestrain, damping).
    modes : int
        Number ``r`` of modes with nonlinear stiffness (cost of a step grows as ``r^4``).
    """

    def __init__(self, fvk: FvKMembrane, modes: int = 20) -> None:
        if not (isinstance(modes, (int, np.integer)) and 1 <= modes <= fvk.n):
            raise InputError(f"modes = {modes!r}: expected an integer in [1, {fvk.n}]")
        self.fvk = fvk
        self.berger = BergerMembrane(fvk.linear, fvk.params)
        sep = self.berger.modes
        tx0, ty0 = fvk.prestress
        self.k = tx0 * sep.lam_x + ty0 * sep.lam_y
        self.index = np.argsort(self.k, kind="stable")[:modes]
        eye = np.zeros((fvk.n, modes))
        eye[self.index, np.arange(modes)] = 1.0
        self.shapes = sep.to_field(eye)  # (n, r) coefficient vectors of the modes
        self.r = modes
        self.tensor = self._cubic_tensor()  # (r, r^3): row i, column (j, k, l)

    def _cubic_tensor(self) -> np.ndarray:
        return cubic_tensor(self.fvk, self.shapes)

    def cubic_force(self, a: np.ndarray) -> np.ndarray:
        """``B(a, a, a)``: the modal nonlinear force of amplitudes ``a`` (r,)."""
        return self.tensor @ np.einsum("j,k,l->jkl", a, a, a).ravel()

    def cubic_jacobian(self, a: np.ndarray) -> np.ndarray:
        """``d B(a, a, a)/da = 3 B(., a, a)`` (r, r)."""
        r = self.r
        return 3.0 * (self.tensor.reshape(r * r, r * r) @ np.outer(a, a).ravel()).reshape(r, r)

    @classmethod
    def from_problem(cls, problem, nodes=None, params=None, modes: int = 20) -> CubicModalMembrane:
        return cls(FvKMembrane(problem, nodes, params), modes)

    @property
    def params(self):
        return self.fvk.params

    def with_params(self, params) -> CubicModalMembrane:
        """Other prestrains / damping: the cubic tensor does not depend on them (no rebuild)."""
        other = CubicModalMembrane.__new__(CubicModalMembrane)
        other.__dict__.update(self.__dict__)
        fvk = FvKMembrane.__new__(FvKMembrane)
        fvk.__dict__.update({k: v for k, v in self.fvk.__dict__.items() if k not in ("damping", "linear_stiffness")})
        fvk.params = params
        other.fvk = fvk
        other.berger = self.berger.with_params(params)
        tx0, ty0 = fvk.prestress
        other.k = tx0 * self.berger.modes.lam_x + ty0 * self.berger.modes.lam_y
        return other

    def simulate(
        self,
        load,
        t_end: float,
        dt: float = 1e-3,
        z0=None,
        v0=None,
        substeps: int = 1,
        sensitivities: bool = False,
        load_directions=None,
        state_directions=None,
        tol: float = 1e-12,
    ) -> BergerTrajectory:
        """Response from ``(z0, v0)`` under load coefficients ``(n,)`` or ``t -> (n,)``.

        Arguments and result as :func:`~wingopt.membrane.berger_sim.simulate_berger` (the
        ``tensions`` are the membrane averages of ``N_x, N_y``, exact for FvK:
        ``C ((eps0_x + s_x) + nu (eps0_y + s_y))``).
        """
        if not (np.isfinite(t_end) and t_end > 0 and np.isfinite(dt) and dt > 0):
            raise InputError(f"t_end = {t_end!r}, dt = {dt!r}: expected positive durations (s)")
        if not (isinstance(substeps, (int, np.integer)) and substeps >= 1):
            raise InputError(f"substeps = {substeps!r}: expected an integer >= 1")
        par, mat, modes, bm = self.fvk.params, self.fvk.problem.material, self.berger.modes, self.berger
        c = par.viscous_scale * mat.viscous + par.kelvin_voigt_scale * mat.kelvin_voigt * self.k
        samples = int(round(t_end / dt))
        h = dt / substeps
        E, dEk, dEc = _step_matrices(bm.rho_h, self.k, c, h, sensitivities)
        Phi, G0, G1 = E[:, :2, :2], E[:, :2, 2] - E[:, :2, 3], E[:, :2, 3]
        times = np.arange(samples * substeps + 1) * h
        P = _load_samples(bm, load, times)
        n, idx, r = self.fvk.n, self.index, self.r
        q = np.zeros(n) if z0 is None else modes.to_modal(np.asarray(z0, float))
        v = np.zeros(n) if v0 is None else modes.to_modal(np.asarray(v0, float))
        g1 = G1[idx, 0]
        N0 = np.zeros(n)
        N0[idx] = self.cubic_force(q[idx])
        J0 = self.cubic_jacobian(q[idx])
        Q, Vq = np.empty((samples + 1, n)), np.empty((samples + 1, n))
        Q[0], Vq[0] = q, v
        if sensitivities:
            sens = _Sensitivity.setup(bm, self.k, dEk, dEc, load_directions, state_directions)
            Sq, Sv = sens.Sq0, sens.Sv0
            SQ = np.empty((samples + 1,) + Sq.shape)
            SQ[0] = Sq
        step, iters = 0, 0
        for s in range(samples):
            for _ in range(substeps):
                f0 = P[step] - N0
                base = Phi[:, 0, 0] * q + Phi[:, 0, 1] * v + G0[:, 0] * f0 + G1[:, 0] * P[step + 1]
                a = (base - G1[:, 0] * N0)[idx]
                for _it in range(40):
                    J1 = self.cubic_jacobian(a)
                    res = a - base[idx] + g1 * self.cubic_force(a)
                    da = -np.linalg.solve(np.eye(r) + g1[:, None] * J1, res)
                    a = a + da
                    iters += 1
                    if np.max(np.abs(da)) <= tol * max(np.max(np.abs(a)), 1e-300):
                        break
                else:
                    raise SolverError(
                        "cubic modal step", f"Newton did not converge at t = {times[step]:.4g} s", "add substeps"
                    )
                N1 = np.zeros(n)
                N1[idx] = self.cubic_force(a)
                J1 = self.cubic_jacobian(a)
                q1 = base - G1[:, 0] * N1  # exact for the linear modes; equals a on the nonlinear ones
                f1 = P[step + 1] - N1
                v1 = Phi[:, 1, 0] * q + Phi[:, 1, 1] * v + G0[:, 1] * f0 + G1[:, 1] * f1
                if sensitivities:

                    def jn(S, J):
                        out = np.zeros_like(S)
                        out[idx] = J @ S[idx]
                        return out

                    def solve1(rhs, J=J1):
                        out = rhs.copy()
                        out[idx] = np.linalg.solve(np.eye(r) + g1[:, None] * J, rhs[idx])
                        return out

                    Sq, Sv = sens.step(
                        q, v, f0, f1, Sq, Sv, Phi, G0, G1, lambda S, J=J0: jn(S, J), lambda S, J=J1: jn(S, J), solve1
                    )
                q, v, N0, J0 = q1, v1, N1, J1
                step += 1
            Q[s + 1], Vq[s + 1] = q, v
            if sensitivities:
                SQ[s + 1] = Sq
        log.debug("cubic modal (r = %d): %d samples, %d Newton iterations", r, samples, iters)
        Z, Zd = modes.to_field(Q.T).T, modes.to_field(Vq.T).T
        A, C, nu = bm.area, bm.C, bm.nu
        sx = np.einsum("tk,k,tk->t", Q, modes.lam_x, Q) / (2 * A)
        sy = np.einsum("tk,k,tk->t", Q, modes.lam_y, Q) / (2 * A)
        ex, ey = par.eps0_x + sx, par.eps0_y + sy
        T = np.column_stack([C * (ex + nu * ey), C * (ey + nu * ex)])
        out = bm.linear.sensors.outputs(Z)
        if not sensitivities:
            return BergerTrajectory(times[::substeps], Z, Zd, out, T)
        dZ, dout = _sensitivity_outputs(bm, Z, SQ)
        return BergerTrajectory(times[::substeps], Z, Zd, out, T, dZ, dout, sens.names)
