"""The operators every full-order nonlinear membrane shares: Grams of the slopes, prestress, damping."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from wingopt.membrane.parameters import prestress_tensions

__all__ = ["PrestressedOperators", "SeparableModes"]


@dataclass(frozen=True, eq=False)
class SeparableModes:
    """``V = Vx⊗Vy`` (M-orthonormal) and the 1-D eigenvalues ``lx, ly`` of ``Gx, Gy`` against ``M``."""

    vx: np.ndarray
    vy: np.ndarray
    lam_x: np.ndarray  # (n,) eigenvalue of Gx for each 2-D mode (lx_i repeated over j)
    lam_y: np.ndarray
    mx: np.ndarray  # 1-D Gram matrices (dense), for q = V^T M z
    my: np.ndarray

    @classmethod
    def build(cls, space) -> SeparableModes:
        mx, kx = space.bx.gram(0, 0).toarray(), space.bx.gram(1, 1).toarray()
        my, ky = space.by.gram(0, 0).toarray(), space.by.gram(1, 1).toarray()
        lx, vx = sla.eigh(kx, mx)
        ly, vy = sla.eigh(ky, my)
        return cls(vx, vy, np.repeat(lx, ly.size), np.tile(ly, lx.size), mx, my)

    @property
    def shape(self) -> tuple[int, int]:
        return self.vx.shape[0], self.vy.shape[0]

    def _apply(self, left: np.ndarray, right: np.ndarray, a: np.ndarray) -> np.ndarray:
        """``(left ⊗ right) a`` for ``a`` of shape ``(n,)`` or ``(n, k)`` (sum factorisation)."""
        nx, ny = left.shape[1], right.shape[1]
        if a.ndim == 1:
            return (left @ a.reshape(nx, ny) @ right.T).ravel()
        k = a.shape[1]
        X = (left @ a.reshape(nx, ny * k)).reshape(left.shape[0], ny, k)
        return np.einsum("jb,abk->ajk", right, X).reshape(left.shape[0] * right.shape[0], k)

    def to_field(self, q: np.ndarray) -> np.ndarray:
        """``z = V q`` for ``q`` of shape ``(n,)`` or ``(n, k)``."""
        return self._apply(self.vx, self.vy, q)

    def to_modal(self, z: np.ndarray) -> np.ndarray:
        """``q = V^T M z`` (the M-orthogonal projection) for ``(n,)`` or ``(n, k)``."""
        return self._apply(self.vx.T @ self.mx, self.vy.T @ self.my, z)

    def to_modal_force(self, p: np.ndarray) -> np.ndarray:
        """``V^T p`` for a force vector ``p`` (``(n,)`` or ``(n, k)``)."""
        return self._apply(self.vx.T, self.vy.T, p)


class PrestressedOperators:
    """The operators every nonlinear membrane shares: Grams of the slopes, prestress, damping.

    Base of :class:`~wingopt.membrane.full.berger.BergerMembrane` and
    :class:`~wingopt.membrane.full.fvk.FvKMembrane`, which set ``linear`` (the linear
    :class:`~wingopt.membrane.MembraneModel` of the mesh), ``space``, ``problem`` and ``params``.
    """

    @cached_property
    def modes(self) -> SeparableModes:
        """The separable modes of the space (the full-order integrator's coordinates)."""
        return SeparableModes.build(self.space)

    @cached_property
    def gx(self) -> sp.csr_matrix:
        """``Gx = ∫ phi_x phi_x^T`` (Kronecker product of 1-D Grams)."""
        sx = self.space
        return sp.kron(sx.bx.gram(1, 1), sx.by.gram(0, 0), format="csr")

    @cached_property
    def gy(self) -> sp.csr_matrix:
        """``Gy = ∫ phi_y phi_y^T``."""
        sx = self.space
        return sp.kron(sx.bx.gram(0, 0), sx.by.gram(1, 1), format="csr")

    @property
    def gram(self) -> sp.csr_matrix:
        return self.linear.gram

    @property
    def mass(self) -> sp.csr_matrix:
        return self.linear.mass

    @property
    def prestress(self) -> tuple[float, float]:
        return prestress_tensions(self.problem.material, self.params)

    @cached_property
    def linear_stiffness(self) -> sp.csr_matrix:
        """``K_T0 = Tx0 Gx + Ty0 Gy``: the small-deflection limit of the tangent."""
        tx, ty = self.prestress
        return (tx * self.gx + ty * self.gy).tocsr()

    @cached_property
    def damping(self) -> sp.csr_matrix:
        """``s_v gamma M + s_kv eta K_T0`` (the linear model's damping at the prestress, scaled)."""
        mat, p = self.problem.material, self.params
        return (
            p.viscous_scale * mat.viscous * self.gram + p.kelvin_voigt_scale * mat.kelvin_voigt * self.linear_stiffness
        ).tocsr()
