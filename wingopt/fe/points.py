"""Weak forms with coefficients that vary inside the elements: a space's basis at its Gauss points.

:func:`wingopt.fe.assemble` integrates forms whose coefficients are constant per element; the
geometrically nonlinear membrane (:mod:`wingopt.membrane.full.fvk`) needs coefficients that are
fields (the stresses of the current deflection). :class:`PointOperators` evaluates fields at every
Gauss point, integrates point data against the basis, and assembles such forms.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from wingopt.fe.bspline import gauss_legendre

__all__ = ["PointOperators"]


@dataclass(frozen=True, eq=False)
class PointOperators:
    """A tensor space's basis at the tensor grid of Gauss points: fields, weak forms, matrices.

    The points are ``(xq_i, yq_j)`` with ``j`` fastest. Fields and weak-form vectors are
    evaluated by sum factorisation (``B1x Z B0y^T``: small dense products). Matrices of forms
    ``∫ c(x) d_a(phi) d_b(phi)^T`` with point coefficients ``c`` are assembled element by element
    as one dense product (the local splines are the same on every element of a uniform mesh) and
    one scatter, like :func:`wingopt.fe.assemble` but for coefficients that vary in the element.
    """

    space: object
    x: tuple[np.ndarray, np.ndarray]  # 1-D values and slopes at the x points, (nqx, nx)
    y: tuple[np.ndarray, np.ndarray]
    weights: np.ndarray
    order: int

    @classmethod
    def build(cls, space, order: int = 5) -> PointOperators:
        t, wt = gauss_legendre(order)
        mats, wts = [], []
        for b in (space.bx, space.by):
            xq = ((np.arange(b.n_elements)[:, None] + t[None, :]) * b.h).ravel()
            mats.append((b.matrix(xq, 0).toarray(), b.matrix(xq, 1).toarray()))
            wts.append(np.tile(wt * b.h, b.n_elements))
        return cls(space, mats[0], mats[1], np.outer(wts[0], wts[1]).ravel(), order)

    @property
    def shape(self) -> tuple[int, int]:
        return self.space.shape

    def gradients(self, coefs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`gradient` of many fields at once: ``coefs`` ``(n, k)`` -> two ``(k, n_points)``."""
        nx, ny = self.shape
        Z = coefs.reshape(nx, ny, -1)
        gx = np.einsum("pa,abk,qb->kpq", self.x[1], Z, self.y[0], optimize=True)
        gy = np.einsum("pa,abk,qb->kpq", self.x[0], Z, self.y[1], optimize=True)
        return gx.reshape(gx.shape[0], -1), gy.reshape(gy.shape[0], -1)

    def divergences(self, ax: np.ndarray, ay: np.ndarray) -> np.ndarray:
        """:meth:`divergence` of many point data at once: ``ax, ay`` ``(k, n_points)`` -> ``(n, k)``."""
        nq = (self.x[0].shape[0], self.y[0].shape[0])
        AX, AY = ax.reshape(-1, *nq), ay.reshape(-1, *nq)
        out = np.einsum("pa,kpq,qb->abk", self.x[1], AX, self.y[0], optimize=True)
        out += np.einsum("pa,kpq,qb->abk", self.x[0], AY, self.y[1], optimize=True)
        return out.reshape(-1, out.shape[-1])

    def gradient(self, coef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(f_x, f_y)`` at all points of the field with coefficients ``coef``."""
        Z = coef.reshape(self.shape)
        return (self.x[1] @ Z @ self.y[0].T).ravel(), (self.x[0] @ Z @ self.y[1].T).ravel()

    def divergence(self, ax: np.ndarray, ay: np.ndarray) -> np.ndarray:
        """``∫ (a_x phi_x + a_y phi_y)`` for point data ``a_x, a_y`` already multiplied by the weights."""
        nq = (self.x[0].shape[0], self.y[0].shape[0])
        return (self.x[1].T @ ax.reshape(nq) @ self.y[0] + self.x[0].T @ ay.reshape(nq) @ self.y[1]).ravel()

    @cached_property
    def _local(self):
        """Local products ``P_ab[q, (i, j)]`` of the 16 element splines, and the scatter indices."""
        sp_, o = self.space, self.order
        t, _ = gauss_legendre(o)
        vals = {}
        for d in ((1, 0), (0, 1)):  # d/dx, d/dy of the 16 local functions at the o*o points
            vx, vy = sp_.bx.local_values(None, t, d[0]), sp_.by.local_values(None, t, d[1])
            vals[d] = np.einsum("pa,qb->pqab", vx, vy).reshape(o * o, 16)
        keys = {"x": (1, 0), "y": (0, 1)}
        prod = {
            a + b: np.einsum("qi,qj->qij", vals[keys[a]], vals[keys[b]]).reshape(o * o, 256) for a in "xy" for b in "xy"
        }
        ex, ey = np.meshgrid(np.arange(sp_.bx.n_elements), np.arange(sp_.by.n_elements), indexing="ij")
        dofs = sp_.local_dofs(ex.ravel(), ey.ravel())
        rows, cols = np.repeat(dofs, 16, axis=1).ravel(), np.tile(dofs, (1, 16)).ravel()
        return prod, rows, cols

    def matrix(self, *terms: tuple[str, np.ndarray]) -> sp.csr_matrix:
        """``Σ ∫ c d_a(phi) d_b(phi)^T`` for terms ``("xy", c)`` etc.: ``a, b`` in ``x, y``, ``c`` at the points."""
        prod, rows, cols = self._local
        nex, ney, o = self.space.bx.n_elements, self.space.by.n_elements, self.order
        local = 0.0
        for ab, c in terms:
            cw = (np.broadcast_to(c, self.weights.shape) * self.weights).reshape(nex, o, ney, o)
            local = local + cw.transpose(0, 2, 1, 3).reshape(nex * ney, o * o) @ prod[ab]
        n_full = self.space.n_full
        full = sp.csr_matrix((local.ravel(), (rows, cols)), shape=(n_full, n_full))
        T = self.space.transform
        return (T.T @ full @ T).tocsr()
