"""The modal membranes' force laws: the only thing the Berger and the FvK models do differently.

Each law gives, at modal displacements ``q``, the secant stiffness ``kk`` (the prestress part ``k0``
plus the deflection's own stiffening on the diagonal) and an off-diagonal force ``R`` held over a
step, so that the internal force is ``kk * q + R``; and their tangents along directions ``dq``
``(m, P)`` (mode-major, so that the loops over directions are contiguous). Only the first ``r``
modes ("moving" modes) change stiffness; ``r = 0`` is the linear membrane.

* Berger (:data:`BERGER`, uniform tension): ``kk = k0 + sx kxs + sy kys`` with the mean stretches
  ``sx = sum q_j^2 kx_j``, ``sy = sum q_j^2 ky_j``; no off-diagonal force; every mode moves
  (``r = m``). ``K`` ``(4, m)`` holds the rows ``kx, ky, kxs, kys``.
* FvK (:data:`CUBIC`): ``N_i(q) = B_ijkl q_j q_k q_l`` on the ``r`` cubic modes; the secant
  ``S_ij = B_ijkl q_k q_l`` gives ``kk = k0 + diag(S)`` and ``R = S q - diag(S) q``. The tensor is
  taken on the ``r (r + 1) / 2`` pairs ``i <= j`` (``Tc``, :func:`pair_tensor`), a quarter of the
  full product; ``Bd[i, k, l] = B_iikl`` gives the diagonal's tangent.

A law is the tuple ``(kind, r, Tc, Bd, K)`` the compiled step loop (:mod:`.kernels`) takes; the
arrays a law does not use are empty.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["BERGER", "CUBIC", "pair_tensor", "stiffness", "stiffness_tangent"]

BERGER = 0
CUBIC = 1


def pair_tensor(tensor: np.ndarray, r: int) -> np.ndarray:
    """``Tc[a, b] = w_b B[pair_a, pair_b]`` on the pairs ``i <= j`` (row-major), ``(r(r+1)/2,) * 2``
    (``w = 2`` off the diagonal: the pair ``(k, l)`` stands for ``(l, k)`` too)."""
    i, j = np.triu_indices(r)
    B = tensor.reshape(r, r, r, r)
    w = np.where(i == j, 1.0, 2.0)
    return np.ascontiguousarray(B[i, j][:, i, j] * w[None, :])


@njit(cache=True)
def _secant(x, Tc, S):
    """Fill ``S`` (r, r) with ``B_ijkl x_k x_l``."""
    r = x.size
    aa = np.empty(r * (r + 1) // 2, dtype=x.dtype)
    p = 0
    for k in range(r):
        for l in range(k, r):
            aa[p] = x[k] * x[l]
            p += 1
    s = Tc @ aa
    p = 0
    for i in range(r):
        for j in range(i, r):
            S[i, j] = s[p]
            S[j, i] = s[p]
            p += 1


@njit(cache=True)
def stiffness(law, q, k0, S, kk, R):
    """Secant stiffness ``kk`` and off-diagonal force ``R`` at ``q`` (``S``: the cubic law's work array)."""
    kind, r, Tc, _, K = law
    kk[:] = k0
    R[:] = 0.0
    if r == 0:
        return
    if kind == BERGER:
        sx = q[0] * 0.0
        sy = q[0] * 0.0
        for j in range(q.size):
            qq = q[j] * q[j]
            sx += qq * K[0, j]
            sy += qq * K[1, j]
        for i in range(r):
            kk[i] = k0[i] + sx * K[2, i] + sy * K[3, i]
        return
    _secant(q[:r], Tc, S)
    for i in range(r):
        kk[i] += S[i, i]
        acc = q[0] * 0.0
        for j in range(r):
            if j != i:
                acc += S[i, j] * q[j]
        R[i] = acc


@njit(cache=True)
def stiffness_tangent(law, q, dq, k0, dk0, S, kk, R, dk, dR):
    """:func:`stiffness` and, on the moving modes, its tangent along ``dq`` ``(m, P)``: ``dk, dR``
    ``(r, P)`` (the other modes' stiffness tangent is ``dk0``, their force zero)."""
    stiffness(law, q, k0, S, kk, R)
    kind, r, _, Bd, K = law
    m, P = dq.shape
    if r == 0 or P == 0:
        return
    if kind == BERGER:
        gx = np.zeros(P, q.dtype)
        gy = np.zeros(P, q.dtype)
        for j in range(m):
            wx, wy, dqj = 2.0 * K[0, j] * q[j], 2.0 * K[1, j] * q[j], dq[j]
            for p in range(P):
                gx[p] += wx * dqj[p]
                gy[p] += wy * dqj[p]
        for i in range(r):
            dki, dRi, d0 = dk[i], dR[i], dk0[i]
            for p in range(P):
                dki[p] = d0[p] + gx[p] * K[2, i] + gy[p] * K[3, i]
                dRi[p] = 0.0
        return
    W = np.zeros((r, r), q.dtype)  # W[i, k] = B_iikl x_l
    for i in range(r):
        for k in range(r):
            acc = q[0] * 0.0
            for l in range(r):
                acc += Bd[i, k, l] * q[l]
            W[i, k] = acc
    for i in range(r):
        dki, dRi = dk[i], dR[i]
        dRi[:] = 0.0
        for p in range(P):
            dki[p] = 0.0
        for k in range(r):
            w, sk, dqk = 2.0 * W[i, k], S[k, i], dq[k]
            for p in range(P):
                dki[p] += w * dqk[p]
                dRi[p] += sk * dqk[p]
        qi, sii, d0, dqi = q[i], S[i, i], dk0[i], dq[i]
        for p in range(P):
            # S symmetric: dN = 3 S dx; the diagonal part moves to the stiffness
            dRi[p] = 3.0 * dRi[p] - dki[p] * qi - sii * dqi[p]
            dki[p] += d0[p]
