"""Cubic modal Föppl–von Kármán membrane, with exact sensitivities.

The FvK in-plane problem is linear, so the deflection-induced out-of-plane force is exactly cubic
(docs/membrane_nonlinear.md §2b). On the ``r`` lowest modes of a
:class:`~wingopt.membrane.modal.base.ModalMembrane` the Galerkin force is ``N_i(q) = B_ijkl q_j q_k q_l``
with the tensor of :func:`~wingopt.membrane.modal.cubic.cubic_tensor`, built once on the model's
mesh from the full FvK membrane's in-plane operator; the higher modes respond linearly at the
prestress. The tensor does not depend on the prestrains or the damping: they enter the linear
part only.

Integration (explicit, second order): ``N(q) = S(q) q`` with the secant matrix
``S_ij = B_ijkl q_k q_l``. Its diagonal joins each oscillator's stiffness (for a uniform in-plane
stress it *is* Berger's tension term), the off-diagonal rest ``R = N - diag(S) q`` is a force held
over the step; both are taken at the mean of the step start and the predicted end
(predictor-corrector). The forward sensitivities differentiate exactly this integrator
(:meth:`FvKModal.simulate_tangent`, checked against complex steps). Real single trajectories and
the tangent run in compiled loops (:mod:`~wingopt.membrane.modal.kernels`, the same arithmetic);
complex and batched runs use the NumPy loops here.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError, SolverError
from wingopt.membrane.full.fvk import FvKMembrane
from wingopt.membrane.modal.base import ModalMembrane
from wingopt.membrane.modal.cubic import cubic_tensor
from wingopt.membrane.modal.kernels import (
    SETTLE_TOL,
    SETTLE_TOL_TANGENT,
    fvk_tangent,
    fvk_trajectory,
    pair_tensor,
    settled_from,
)
from wingopt.membrane.modal.oscillator import oscillator_step, oscillator_tangent, prestress_terms
from wingopt.membrane.modal.tangent import ForceTangent
from wingopt.membrane.model import MembraneModel

__all__ = ["FvKModal"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class FvKModal(ModalMembrane):
    """Modal membrane with FvK's exact cubic stiffness on its ``cubic_modes`` lowest modes.

    Attributes (besides :class:`ModalMembrane`'s)
    -----------------------------------------------
    tensor : ndarray ``(r^2, r^2)``
        ``B[(i, j), (k, l)]``, fully symmetric (a potential's fourth derivative).
    diag_tensor : ndarray ``(r, r, r)``
        ``B[i, i, k, l]`` (the secant diagonal's quadratic form).
    """

    tensor: np.ndarray | None = None
    diag_tensor: np.ndarray | None = None
    pair_tensor: np.ndarray | None = None

    @classmethod
    def build(
        cls,
        model: MembraneModel,
        modes: int = 48,
        dt: float | None = None,
        substeps: int = 1,
        cubic_modes: int = 16,
    ) -> FvKModal:
        """The ``modes`` lowest modes of ``model`` (all integrated), the ``cubic_modes`` lowest with
        FvK's cubic stiffness (``cubic_modes^2 / 2`` in-plane solves on ``model``'s mesh)."""
        base = cls.modal_fields(model, modes, dt, substeps)
        r, m = cubic_modes, base["kx"].size
        if not (isinstance(r, (int, np.integer)) and 1 <= r <= m):
            raise InputError(f"cubic_modes = {r!r}: expected an integer in [1, {m}]")
        fvk = FvKMembrane(model.problem)
        if fvk.n != model.n:  # pragma: no cover - same problem, same mesh
            raise InputError(f"FvK model: {fvk.n} dofs, expected {model.n}")
        B = cubic_tensor(fvk, base["shapes"][:, :r]).reshape(r, r, r, r)
        idx = np.arange(r)
        T = B.reshape(r * r, r * r)
        return cls(**base, tensor=T, diag_tensor=np.ascontiguousarray(B[idx, idx]), pair_tensor=pair_tensor(T, r))

    @property
    def cubic_modes(self) -> int:
        return self.diag_tensor.shape[0]

    def cubic_force(self, q: np.ndarray) -> np.ndarray:
        """``N(q)`` ``(..., m)`` (zero beyond the cubic modes)."""
        d, R = self._secant(q)
        out = np.zeros(np.shape(q), dtype=np.result_type(q, float))
        r = self.cubic_modes
        out[..., :r] = d * q[..., :r] + R
        return out

    def _secant(self, q):
        """Secant diagonal ``d`` and off-diagonal force ``R`` on the cubic modes (``(..., r)`` each)."""
        r = self.cubic_modes
        a = q[..., :r]
        aa = (a[..., :, None] * a[..., None, :]).reshape(a.shape[:-1] + (r * r,))
        S = (aa @ self.tensor).reshape(a.shape[:-1] + (r, r))
        d = np.einsum("...ii->...i", S)
        return d, np.einsum("...ij,...j->...i", S, a) - d * a

    def internal_force(self, q, ex, ey, nonlinear: bool = True):
        """``k0 q + N(q)`` and its Jacobian ``diag(k0) + 3 S(q)`` (``S`` the symmetric secant)."""
        k0 = self.omega(ex, ey) ** 2
        F, J = k0 * q, np.diag(k0)
        if nonlinear:
            r = self.cubic_modes
            a = q[:r]
            S = ((a[:, None] * a[None, :]).ravel() @ self.tensor).reshape(r, r)
            F = F.copy()
            F[:r] += S @ a
            J[:r, :r] += 3.0 * S
        return F, J

    def equilibrium(self, u, params=None, nonlinear: bool = True) -> np.ndarray:
        """Static modal displacements under the modal force ``u``: the modes beyond the cubic ones are
        linear and uncoupled (``q_j = u_j / k0_j``); Newton (halving steps) on the cubic ones only."""
        par = self.nominal if params is None else params
        u = np.asarray(u, dtype=float)
        k0 = self.omega(par.eps0_x, par.eps0_y) ** 2
        q = u / k0
        r = self.cubic_modes if nonlinear else 0
        if not r:
            return q
        a, ua, ka, T = q[:r].copy(), u[:r], k0[:r], self.tensor
        scale = max(np.linalg.norm(ua), 1e-300)

        def residual(a):
            S = ((a[:, None] * a[None, :]).ravel() @ T).reshape(r, r)
            return ka * a + S @ a - ua, S

        res, S = residual(a)
        for _ in range(100):
            norm = np.linalg.norm(res)
            if norm <= 1e-12 * scale:
                q[:r] = a
                return q
            step = -np.linalg.solve(np.diag(ka) + 3.0 * S, res)
            t = 1.0
            while t > 1e-6:
                trial, St = residual(a + t * step)
                if np.linalg.norm(trial) < norm:
                    break
                t *= 0.5
            a, res, S = a + t * step, trial, St
        raise SolverError(
            "FvKModal static solve", f"residual {np.linalg.norm(res) / scale:.1e} after 100 steps", "reduce the load"
        )

    def solve_tangent(self, q, params, rhs: np.ndarray) -> np.ndarray:
        """``F_q^-1 rhs`` at the static state ``q``: the cubic block's dense solve, the rest diagonal."""
        par = self.nominal if params is None else params
        k0 = self.omega(par.eps0_x, par.eps0_y) ** 2
        r = self.cubic_modes
        a = q[:r]
        S = ((a[:, None] * a[None, :]).ravel() @ self.tensor).reshape(r, r)
        out = rhs / (k0[:, None] if rhs.ndim == 2 else k0)
        out[:r] = np.linalg.solve(np.diag(k0[:r]) + 3.0 * S, rhs[:r])
        return out

    # -- dynamics --------------------------------------------------------------------------
    def simulate(self, q0, v0, forces, ex, ey, damping=1.0, nonlinear: bool = True):
        """Modal displacements ``(N + 1, ..., m)`` at every sample (arguments as
        :meth:`~wingopt.membrane.modal.berger.BergerModal.simulate`; ``nonlinear=False``: the linear
        model, the Berger model's without its stretch)."""
        forces = np.asarray(forces)
        N, m, r = forces.shape[0], self.m, self.cubic_modes
        dtype = np.result_type(q0, v0, forces, ex, ey, damping, float)
        if dtype == np.float64:
            return self._simulate_compiled(q0, v0, forces, ex, ey, damping, nonlinear)
        r = r if nonlinear else 0
        q = np.array(q0, dtype=dtype)
        v = np.array(v0, dtype=dtype)
        ex = np.asarray(ex, dtype=dtype)[..., None]
        ey = np.asarray(ey, dtype=dtype)[..., None]
        c = self._coefficients(ex[..., 0], ey[..., 0], np.asarray(damping, dtype=dtype))
        nu, C = self.model.problem.material.poisson_ratio, self.stiffness_c
        k0 = C * ((ex + nu * ey) * self.kx + (ey + nu * ex) * self.ky)
        h = self.dt / self.substeps
        e = np.exp(-0.5 * c * h)
        shape = np.broadcast_shapes(q.shape[:-1], forces.shape[1:-1], k0.shape[:-1])
        Q = np.empty((N + 1,) + shape + (m,), dtype=dtype)
        Q[0] = q

        def stiff(q):
            kk = np.array(np.broadcast_to(k0, shape + (m,)), dtype=dtype)
            Rf = np.zeros(shape + (m,), dtype=dtype)
            if r:
                d, R = self._secant(q)
                kk[..., :r] += d
                Rf[..., :r] = R
            return kk, Rf

        with np.errstate(over="ignore", invalid="ignore"):  # a diverging trial step gives non-finite costs
            for k in range(N):
                u = forces[k]
                for _ in range(self.substeps):
                    k1, R1 = stiff(q)
                    qp, _ = oscillator_step(q, v, u - R1, k1, c, h, e)
                    k2, R2 = stiff(qp)
                    q, v = oscillator_step(q, v, u - 0.5 * (R1 + R2), 0.5 * (k1 + k2), c, h, e)
                Q[k + 1] = q
        return Q

    def _cubic(self, nonlinear: bool) -> tuple[int, np.ndarray, np.ndarray]:
        """Cubic modes, pair tensor and diagonal tensor of the compiled loops (none: the linear model)."""
        if nonlinear:
            return self.cubic_modes, self.pair_tensor, self.diag_tensor
        return 0, np.zeros((0, 0)), np.zeros((0, 0, 0))

    def _simulate_compiled(self, q0, v0, forces, ex, ey, damping, nonlinear):
        """:meth:`simulate` for real arguments: each trajectory of the batch by the compiled loop."""
        N, m = forces.shape[0], self.m
        shape = np.broadcast_shapes(np.shape(q0)[:-1], np.shape(v0)[:-1], forces.shape[1:-1], np.shape(ex),
                                    np.shape(ey), np.shape(damping))  # fmt: skip
        q0, v0 = np.broadcast_to(q0, shape + (m,)), np.broadcast_to(v0, shape + (m,))
        F = np.broadcast_to(forces, (N,) + shape + (m,))
        ex, ey, damping = (np.broadcast_to(np.asarray(x, float), shape) for x in (ex, ey, damping))
        Q = np.empty((N + 1,) + shape + (m,))
        h = self.dt / self.substeps
        r, Tc, _ = self._cubic(nonlinear)
        with np.errstate(over="ignore", invalid="ignore"):  # a diverging trial step gives non-finite costs
            for i in np.ndindex(shape):
                _, k0, _, a, _, e = prestress_terms(self, ex[i], ey[i], damping[i], np.zeros((3, 0)))
                Fi = np.ascontiguousarray(F[(slice(None),) + i])
                Q[(slice(None),) + i] = fvk_trajectory(
                    np.array(q0[i], float), np.array(v0[i], float), Fi, k0, a, e, h, self.substeps, r, Tc,
                    settled_from(Fi), SETTLE_TOL,
                )  # fmt: skip
        return Q

    def simulate_tangent(self, q0, v0, forces, ex, ey, damping, dq0, dv0, dpar, dforces, nonlinear: bool = True):
        """Trajectory ``(N+1, m)`` and its exact tangents ``(N+1, P, m)``; arguments as
        :func:`~wingopt.membrane.modal.tangent.simulate_tangent`."""
        h, k0, dk0, a, da, e = prestress_terms(self, ex, ey, damping, dpar)
        if isinstance(dforces, ForceTangent):
            f = dforces
            r, Tc, Bd = self._cubic(nonlinear)
            mm = lambda x: np.ascontiguousarray(np.asarray(x, float).T)  # noqa: E731 - mode-major for the kernel
            Q, dQ = fvk_tangent(
                np.asarray(q0, float), np.asarray(v0, float), np.ascontiguousarray(forces, float), k0, mm(dk0), a,
                mm(da), e, h, self.substeps, r, Tc, Bd, mm(dq0), mm(dv0), np.asarray(f.amp, float), mm(f.base),
                np.ascontiguousarray(f.hats, float), int(f.g0), np.asarray(f.fc, float),
                settled_from(forces, f.amp, f.hats), SETTLE_TOL, SETTLE_TOL_TANGENT,
            )  # fmt: skip
            return Q, dQ.transpose(0, 2, 1)
        m, r = self.m, self.cubic_modes if nonlinear else 0
        T, Bd = self.tensor, self.diag_tensor
        N, P = forces.shape[0], dq0.shape[0]
        Q, dQ = np.empty((N + 1, m)), np.empty((N + 1, P, m))
        q, v, dq, dv = np.array(q0, float), np.array(v0, float), np.array(dq0, float), np.array(dv0, float)
        Q[0], dQ[0] = q, dq

        def stiff(q, dq):
            if not r:
                return k0, dk0, np.zeros(m), np.zeros((P, m))
            x, dx = q[:r], dq[:, :r]
            S = (np.outer(x, x).ravel() @ T).reshape(r, r)
            d = np.diag(S).copy()
            ddiag = 2.0 * dx @ (Bd @ x).T  # d/dq of B_iikl x_k x_l along each direction
            kk, dk = k0.copy(), dk0.copy()
            kk[:r] += d
            dk[:, :r] += ddiag
            R, dR = np.zeros(m), np.zeros((P, m))
            R[:r] = S @ x - d * x
            dR[:, :r] = 3.0 * dx @ S - ddiag * x - d * dx  # S symmetric: dN = 3 S dx
            return kk, dk, R, dR

        for j in range(N):
            u, du = forces[j], dforces(j)
            for _ in range(self.substeps):
                k1, dk1, R1, dR1 = stiff(q, dq)
                qp, _, dqp, _ = oscillator_tangent(q, v, u - R1, k1, a, e, h, dq, dv, du - dR1, dk1, da)
                k2, dk2, R2, dR2 = stiff(qp, dqp)
                q, v, dq, dv = oscillator_tangent(
                    q,
                    v,
                    u - 0.5 * (R1 + R2),
                    0.5 * (k1 + k2),
                    a,
                    e,
                    h,
                    dq,
                    dv,
                    du - 0.5 * (dR1 + dR2),
                    0.5 * (dk1 + dk2),
                    da,
                )
            Q[j + 1], dQ[j + 1] = q, dq
        return Q, dQ
