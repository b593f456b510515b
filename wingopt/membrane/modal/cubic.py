"""The Galerkin tensor of the Föppl–von Kármán membrane's cubic force on a few deflection shapes.

The FvK in-plane problem is linear, so ``u, v`` are quadratic in ``w`` and the out-of-plane force
is exactly cubic: ``F(z) = K_T0 z + N(z)``, ``N`` homogeneous of degree 3. On the ``r`` lowest
modes ``Phi`` (M-orthonormal, ``K_T0`` and ``D`` diagonal) the Galerkin projection
``Phi^T N(Phi a) = B(a, a, a)`` is a symmetric cubic form whose tensor is computed once from
``r^2`` in-plane solves. The modal FvK model (:class:`~wingopt.membrane.modal.fvk.FvKModal`) keeps
all its modes: the ``r`` lowest carry the exact cubic stiffness, the others respond linearly
(prestress tension only). As ``r -> n`` it is the FvK model exactly; the truncation error is measured in the docs.
"""

from __future__ import annotations

import numpy as np

from wingopt.membrane.full.fvk import FvKMembrane

__all__ = ["cubic_tensor"]

PAIRS_PER_BLOCK = 48
"""Mode pairs whose in-plane problems are solved together (a few MB of fields per block)."""


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
    # Quadratic strains of each pair j <= k (w = phi_j + phi_k contributes a_j a_k (...)); twice them
    # are the products of slopes the force is tested with.
    J, K = np.triu_indices(r)
    Gx, Gy = gx[J] * gx[K], gy[J] * gy[K]
    Gxy = gx[J] * gy[K] + gy[J] * gx[K]
    Bp = np.empty((J.size, J.size))
    # The pairs' in-plane problems share the factorised stiffness; in blocks of pairs, so that the
    # strain and stress fields of a block stay small (the whole set is ~30 arrays of pairs x points)
    for b in range(0, J.size, PAIRS_PER_BLOCK):
        blk = slice(b, b + PAIRS_PER_BLOCK)
        exp, eyp, ggp = 0.5 * Gx[blk], 0.5 * Gy[blk], 0.5 * Gxy[blk]
        nx, ny, nxy = C * (exp + nu * eyp), C * (eyp + nu * exp), G * ggp
        rhs = np.vstack([o.divergences(W * nx, W * nxy), o.divergences(W * nxy, W * ny)])
        uv = -lu.solve(rhs)
        ux, uy = o.gradients(uv[:n])
        vx, vy = o.gradients(uv[n:])
        exj, eyj, gj = exp + ux, eyp + vy, ggp + uy + vx
        # B[j, k, i, l] = ∫ Sx_jk phi_i,x phi_l,x + Sy_jk phi_i,y phi_l,y + Sxy_jk (phi_i,x phi_l,y + phi_i,y
        # phi_l,x), symmetric in (j, k) and in (i, l): contracted over the pairs only (a quarter of the products)
        Bp[blk] = (W * C * (exj + nu * eyj)) @ Gx.T + (W * C * (eyj + nu * exj)) @ Gy.T + (W * G * gj) @ Gxy.T
    pair = np.empty((r, r), dtype=int)
    pair[J, K] = pair[K, J] = np.arange(J.size)
    B = Bp[pair[:, :, None, None], pair[None, None, :, :]].transpose(2, 0, 1, 3)  # (i, j, k, l)
    perms = ((1, 2, 3), (1, 3, 2), (2, 1, 3), (2, 3, 1), (3, 1, 2), (3, 2, 1))
    B = sum(B.transpose((0,) + p) for p in perms) / 6.0
    return B.reshape(r, r**3)
