"""The reduced membrane model seen by the moving-horizon estimator.

Structure exploited (spec §4): the dynamics are linear and exactly discretised per mode, the
sensors are quadratic. With M-orthonormal modes ``Phi`` (lowest ``m`` kept), modal
displacement ``q`` and velocity ``q'``, and the load entering only through the modal forces
``u = Phi^T G f`` (``G = ∫ phi_w psi_f^T``), the modal displacement at sample ``k`` of a window is
*linear* in the window unknowns ``theta = [q0, q0', u_1 .. u_B]``::

    q_k = a_k * q0 + b_k * q0' + sum_b c_{k,b} * u_b        (element-wise per mode)

with per-mode scalar sequences ``a, b, c`` precomputed once per window length, so each output
``s_{k,i} = q_k^T C^_i q_k`` (``C^_i = Phi^T C_i Phi``) is a quadratic function of a linear map of
``theta`` and Gauss–Newton needs only cheap dense algebra.

Load reduction: the data depend on the load only through ``u``; for given ``u`` the smoothest load
(least ``f^T Lam f``) is ``f = E u`` with ``E = Lam^-1 B^T (B Lam^-1 B^T)^-1``, ``B = Phi^T G``, and
its roughness is ``u^T S^-1 u`` with ``S = B Lam^-1 B^T``. Minimising over ``u`` with this
regulariser is therefore *exactly* the Tikhonov problem over ``f`` for the truncated model, at
``3m`` instead of ``2m + n_f`` unknowns.

Modal truncation error is measured in the tests (the sensor outputs of the steady L3 response
with 60 modes are within 0.1 % of the full model); the deflection estimate adds the static
response of the dropped modes (mode-acceleration correction) so that it is not truncated.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from wingopt.dynamics.reduction import static_residual
from wingopt.errors import InputError
from wingopt.estimation.core.load_space import LoadSpace
from wingopt.estimation.declaration import declaration_of
from wingopt.membrane import MembraneModel

__all__ = ["MHEModel", "WindowBasis", "flush_subnormal"]

log = logging.getLogger(__name__)

_TINY = 1e-250
"""Below this, decaying modal sequences are set to zero (subnormal arithmetic is ~100x slower)."""


def flush_subnormal(a: np.ndarray, tiny: float = _TINY) -> np.ndarray:
    """Zero entries with ``|a| < tiny`` in place and return ``a``.

    High membrane modes decay by ``e^-4`` per millisecond; their transition sequences reach
    subnormal numbers within a few hundred samples, which makes every later product slow.
    """
    a[np.abs(a) < tiny] = 0.0
    return a


@dataclass(frozen=True, eq=False)
class WindowBasis:
    """Per-mode response sequences of a window of ``length`` samples with ``blocks`` load blocks.

    Attributes
    ----------
    a, b : ndarray ``(length, m)``
        Modal displacement at sample ``k`` from a unit initial displacement / velocity.
    c : ndarray ``(blocks, length, m)``
        Modal displacement at sample ``k`` from a unit modal force held during block ``b``
        (block ``b`` covers samples ``[b L, (b+1) L)`` of the window, ``L = length // blocks``;
        the force held from sample ``j`` to ``j+1`` acts on the state from ``j+1`` on).
    """

    length: int
    blocks: int
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray

    @property
    def block_length(self) -> int:
        return self.length // self.blocks


@dataclass(frozen=True, eq=False)
class MHEModel:
    """Modal-truncated membrane model with the load reduced to modal forces.

    Build with :meth:`build`. All arrays are in physical modal units (``q`` in ``sqrt(kg)·m``,
    ``u`` in ``N/sqrt(kg)``); estimators scale them.

    Attributes
    ----------
    model : MembraneModel
    load_space : LoadSpace
    dt : float
    omega, damping : ndarray ``(m,)``
        Undamped circular frequencies and modal damping ``c_j`` (``q'' + c q' + omega^2 q = u``).
    shapes : ndarray ``(n, m)``
    input_matrix : ndarray ``(m, n_f)``
        ``B = Phi^T G``.
    sensor_matrices : ndarray ``(p, m, m)``
        ``C^_i = Phi^T C_i Phi``.
    F, g : ndarray ``(m, 2, 2)``, ``(m, 2)``
        Exact per-mode ZOH: ``[q, q']_{k+1} = F [q, q']_k + g u_k``.
    """

    model: MembraneModel
    load_space: LoadSpace
    dt: float
    omega: np.ndarray
    damping: np.ndarray
    shapes: np.ndarray
    input_matrix: np.ndarray
    sensor_matrices: np.ndarray
    F: np.ndarray
    g: np.ndarray
    ridge: float = 1e-9

    @classmethod
    def build(
        cls, model: MembraneModel, load_space: LoadSpace, modes: int | None = 60, dt: float | None = None
    ) -> MHEModel:
        """Reduce ``model`` to its lowest ``modes`` modes (``None``: all) at sample period ``dt``
        (default: the one its problem declares; the estimators pass their settings' ``declaration.dt``)."""
        n = model.n
        modes = n if modes is None else int(modes)
        if not 1 <= modes <= n:
            raise InputError(f"modes = {modes}: expected 1..{n} for this mesh")
        dt = declaration_of(model.problem).dt if dt is None else float(dt)
        modal = model.modal(modes)
        disc = modal.discretize(dt)
        Phi = modal.shapes
        B = np.asarray((sp.csr_matrix(load_space.coupling).T @ Phi).T)
        Chat = np.stack([Phi.T @ (C @ Phi) for C in model.sensors.matrices])
        return cls(model, load_space, dt, modal.omega, modal.damping, Phi, B, Chat, disc.F, disc.g)

    # -- sizes ---------------------------------------------------------------------------
    @property
    def m(self) -> int:
        return self.omega.size

    @property
    def p(self) -> int:
        return self.sensor_matrices.shape[0]

    @property
    def n_load(self) -> int:
        return self.load_space.n

    # -- load reduction ------------------------------------------------------------------
    @cached_property
    def _lam_factor(self):
        """Sparse LU of ``Lam + ridge * scale * Gram`` (the free-edge ``Lam`` has bilinear null space).

        The ridge only makes the minimum-roughness load unique in the null space of ``Lam``
        (functions ``1, x, y, xy``); it is relative to the smallest non-trivial roughness, far
        below any regularisation weight used.
        """
        ls = self.load_space
        scale = (np.pi / min(ls.space.width, ls.space.height)) ** 4
        A = (ls.regularizer + self.ridge * scale * ls.gram).tocsc()
        return spla.splu(A)

    @cached_property
    def _reduction(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        B = self.input_matrix
        LinvBt = self._lam_factor.solve(np.ascontiguousarray(B.T))  # (n_f, m)
        S = B @ LinvBt
        S = 0.5 * (S + S.T)
        # Symmetric eigendecomposition: S spans many decades (smooth modes are cheap in Lam).
        w, V = sla.eigh(S)
        if w.min() <= 0:
            raise InputError("load space: the retained modes are not excited by this load basis")
        Sinv = (V / w) @ V.T
        E = LinvBt @ Sinv
        return E, 0.5 * (Sinv + Sinv.T), S

    @property
    def load_map(self) -> np.ndarray:
        """``E`` ``(n_f, m)``: the smoothest load coefficients ``f = E u`` with modal forces ``u``."""
        return self._reduction[0]

    @property
    def roughness(self) -> np.ndarray:
        """``S^-1`` ``(m, m)``: ``f^T Lam f`` of ``f = E u`` equals ``u^T S^-1 u``."""
        return self._reduction[1]

    @property
    def roughness_inverse(self) -> np.ndarray:
        """``S = B Lam^-1 B^T``."""
        return self._reduction[2]

    def modal_forces(self, f: np.ndarray) -> np.ndarray:
        """``u = B f``."""
        return self.input_matrix @ f

    def load(self, u: np.ndarray) -> np.ndarray:
        """Load coefficients ``E u`` of modal forces ``(m,)`` or ``(k, m)``."""
        return np.asarray(u) @ self.load_map.T

    @cached_property
    def lift_row(self) -> np.ndarray:
        """``l`` with ``lift = l^T u`` for ``f = E u``."""
        return self.load_map.T @ self.load_space.basis_integrals

    # -- deflection ----------------------------------------------------------------------
    def residual_static(self, f: np.ndarray) -> np.ndarray:
        """Static deflection of the dropped modes under load ``f`` (mode-acceleration correction)."""
        if self.m == self.model.n:
            return np.zeros(self.model.n)
        return static_residual(self.model.system, self.shapes, self.omega, self.load_space.coupling @ f)

    def deflection(self, q: np.ndarray, f: np.ndarray | None = None) -> np.ndarray:
        """Deflection coefficients ``Phi q`` (+ static correction for load ``f``); ``q`` may be ``(k, m)``."""
        z = np.asarray(q) @ self.shapes.T
        if f is not None:
            z = z + self.residual_static(f)
        return z

    def to_modal(self, z: np.ndarray) -> np.ndarray:
        """Modal coordinates of deflection coefficients (mass-orthonormal projection)."""
        return self.shapes.T @ (self.model.mass @ z)

    # -- windows -------------------------------------------------------------------------
    def window(self, length: int, blocks: int = 1) -> WindowBasis:
        """Response sequences for a window of ``length`` samples and ``blocks`` equal load blocks."""
        if length < 1 or blocks < 1 or length % blocks:
            raise InputError(f"window = {length}, blocks = {blocks}: the window must split into equal blocks")
        m, F, g = self.m, self.F, self.g
        a = np.empty((length, m))
        b = np.empty((length, m))
        step = np.empty((length, m))
        sa = np.stack([np.ones(m), np.zeros(m)], axis=1)
        sb = np.stack([np.zeros(m), np.ones(m)], axis=1)
        sc = np.zeros((m, 2))
        for k in range(length):
            a[k], b[k], step[k] = sa[:, 0], sb[:, 0], sc[:, 0]
            sa = flush_subnormal(np.einsum("mij,mj->mi", F, sa))
            sb = flush_subnormal(np.einsum("mij,mj->mi", F, sb))
            sc = np.einsum("mij,mj->mi", F, sc) + g
        L = length // blocks
        c = np.zeros((blocks, length, m))
        for blk in range(blocks):
            start, stop = blk * L, (blk + 1) * L
            c[blk, start:] = step[: length - start]
            c[blk, stop:] -= step[: length - stop]
        return WindowBasis(length, blocks, a, b, c)

    def transition(self, steps: int) -> tuple[np.ndarray, np.ndarray]:
        """``F^steps`` ``(m, 2, 2)`` and the response to a held unit force ``(m, 2)`` over ``steps``."""
        Fs = np.broadcast_to(np.eye(2), (self.m, 2, 2)).copy()
        Gs = np.zeros((self.m, 2))
        for _ in range(steps):
            Gs = np.einsum("mij,mj->mi", self.F, Gs) + self.g
            Fs = flush_subnormal(np.einsum("mij,mjk->mik", self.F, Fs))
        return Fs, Gs

    def modal_trajectory(self, basis: WindowBasis, theta: np.ndarray) -> np.ndarray:
        """``q_k`` ``(length, m)`` of the window unknowns ``theta = [q0, q0', u_1..u_B]``."""
        m = self.m
        Q = basis.a * theta[:m] + basis.b * theta[m : 2 * m]
        U = theta[2 * m :].reshape(basis.blocks, m)
        return Q + np.einsum("bkm,bm->km", basis.c, U)

    @cached_property
    def _sensor_stack(self) -> np.ndarray:
        """``[C^_1, .., C^_p]`` side by side ``(m, p m)``: one matrix product gives every ``C^_i q``."""
        return np.ascontiguousarray(np.concatenate(list(self.sensor_matrices), axis=1))

    def _cq(self, Q: np.ndarray) -> np.ndarray:
        """``C^_i q_k`` for all samples and sensors, ``(length, p, m)`` (the ``C^_i`` are symmetric)."""
        return (Q @ self._sensor_stack).reshape(Q.shape[0], self.p, self.m)

    def outputs(self, Q: np.ndarray) -> np.ndarray:
        """Sensor outputs ``(length, p)`` of modal displacements ``Q`` ``(length, m)``."""
        return np.einsum("kpi,ki->kp", self._cq(Q), Q, optimize=True)

    def outputs_and_jacobian(self, basis: WindowBasis, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Outputs ``(length, p)`` and their Jacobian ``(length, p, dim)`` w.r.t. ``theta``."""
        Q = self.modal_trajectory(basis, theta)
        CQ = self._cq(Q)
        Y = np.einsum("kpi,ki->kp", CQ, Q, optimize=True)
        two = 2.0 * CQ
        parts = [two * basis.a[:, None, :], two * basis.b[:, None, :]]
        parts += [two * basis.c[blk][:, None, :] for blk in range(basis.blocks)]
        return Y, np.concatenate(parts, axis=2)
