"""Cubic modal Föppl–von Kármán membrane, with exact sensitivities.

The FvK in-plane problem is linear, so the deflection-induced out-of-plane force is exactly cubic
(docs/membrane_nonlinear.md §2b). On the ``r`` lowest modes of a
:class:`~wingopt.membrane.modal.base.ModalMembrane` the Galerkin force is ``N_i(q) = B_ijkl q_j q_k q_l``
with the tensor of :func:`~wingopt.membrane.modal.cubic.cubic_tensor`, built once on the model's
mesh from the full FvK membrane's in-plane operator; the higher modes respond linearly at the
prestress. The tensor does not depend on the prestrains or the damping: they enter the linear
part only.

Integration: the modal membranes' one compiled loop (:mod:`.kernels`) with this model's force law
(:data:`~.laws.CUBIC`): ``N(q) = S(q) q`` with the secant matrix ``S_ij = B_ijkl q_k q_l``; its
diagonal joins each oscillator's stiffness (for a uniform in-plane stress it *is* Berger's tension
term), the off-diagonal rest ``R = N - diag(S) q`` is a force held over the step; both are taken at
the mean of the step start and the predicted end (predictor-corrector).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError, SolverError
from wingopt.membrane.full.fvk import FvKMembrane
from wingopt.membrane.modal.base import ModalMembrane
from wingopt.membrane.modal.cubic import cubic_tensor
from wingopt.membrane.modal.laws import CUBIC, pair_tensor
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
    physics = "fvk"
    settles = True

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
    def force_law(self, nonlinear: bool = True, dtype=float) -> tuple:
        """The cubic force on the cubic modes (:data:`~.laws.CUBIC`); none: the linear model."""
        if not nonlinear:
            return CUBIC, 0, np.zeros((0, 0), dtype), np.zeros((0, 0, 0)), np.zeros((0, 0), dtype)
        Tc = self.pair_tensor.astype(dtype, copy=False)
        return CUBIC, self.cubic_modes, Tc, self.diag_tensor, np.zeros((0, 0), dtype)
