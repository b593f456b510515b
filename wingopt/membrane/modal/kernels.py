"""Compiled time loops of the cubic modal FvK model: the trajectory, its exact tangent, one sample.

:func:`fvk_trajectory` and :func:`fvk_tangent` integrate a whole record (the batch estimator);
:func:`fvk_step_tangent` one sample with the velocity tangents too (the streaming EKF,
:class:`~wingopt.membrane.modal.fvk_step.FvKSample`). Tangents are mode-major ``(m, P)``.

The integrator is :class:`~wingopt.membrane.modal.fvk.FvKModal`'s (exact damped
oscillator per mode for a frozen stiffness, predictor-corrector on the secant stiffness and the
off-diagonal cubic force), step for step and formula for formula; the NumPy loops there stay the
reference (complex-step batches) and the tests hold the two together to
rounding. Why compiled: one sample is ~100 small array operations in NumPy, so a 1 s record at
1 kHz costs ~0.5 s per Jacobian in interpreter overhead alone; here it costs the arithmetic.

The cubic force uses the tensor's symmetry: ``S_ij = sum_{k<=l} w_kl B_ijkl x_k x_l`` on the
``r (r + 1) / 2`` pairs ``i <= j`` (``w = 2`` off the diagonal), a quarter of the full product.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["SETTLE_TOL", "SETTLE_TOL_TANGENT", "pair_tensor", "settled_from"]
__all__ += ["fvk_trajectory", "fvk_tangent", "fvk_step_tangent"]


def pair_tensor(tensor: np.ndarray, r: int) -> np.ndarray:
    """``Tc[a, b] = w_b B[pair_a, pair_b]`` on the pairs ``i <= j`` (row-major), ``(r(r+1)/2,) * 2``."""
    i, j = np.triu_indices(r)
    B = tensor.reshape(r, r, r, r)
    w = np.where(i == j, 1.0, 2.0)
    return np.ascontiguousarray(B[i, j][:, i, j] * w[None, :])


@njit(cache=True)
def _secant(x, Tc, S):
    """Fill ``S`` (r, r) with ``B_ijkl x_k x_l``."""
    r = x.size
    n2 = r * (r + 1) // 2
    aa = np.empty(n2)
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
def _cs(zz):
    """``cos(sqrt zz)`` and ``sin(sqrt zz)/sqrt zz`` (cosh/sinh below zero)."""
    if zz > 0:
        rr = np.sqrt(zz)
        return np.cos(rr), np.sin(rr) / rr
    rr = np.sqrt(-zz)
    return np.cosh(rr), np.sinh(rr) / rr


@njit(cache=True)
def _oscillate(q, v, u, k, a, e, h, q1, v1, stop):
    """Exact step of ``q'' + 2a q' + k q = u`` for the modes ``< stop`` into ``q1, v1``."""
    for j in range(stop):
        cz, sz = _cs((k[j] - a[j] * a[j]) * h * h)
        es = e[j] * sz * h
        qe = u[j] / k[j]
        d = q[j] - qe
        q1[j] = qe + (e[j] * cz + a[j] * es) * d + es * v[j]
        v1[j] = (e[j] * cz - a[j] * es) * v[j] - (k[j] * es) * d


@njit(cache=True)
def _stiff(q, k0, r, Tc, S, kk, R):
    """Secant stiffness ``kk`` and off-diagonal cubic force ``R`` at ``q``."""
    _secant(q[:r], Tc, S)
    kk[:] = k0
    R[:] = 0.0
    for i in range(r):
        kk[i] += S[i, i]
        acc = 0.0
        for j in range(r):
            if j != i:
                acc += S[i, j] * q[j]
        R[i] = acc


def settled_from(forces: np.ndarray, amp: np.ndarray | None = None, hats: np.ndarray | None = None) -> int:
    """First interval from which the force (and its tangent) no longer changes (``N``: never)."""
    N = forces.shape[0]
    moving = np.any(forces[1:] != forces[:-1], axis=1)
    if amp is not None:
        moving |= amp[1:N] != amp[: N - 1]
        if hats.shape[1]:
            moving |= np.any(hats[1:N] != hats[: N - 1], axis=1)
    idx = np.flatnonzero(moving)
    return 0 if idx.size == 0 else int(idx[-1]) + 1


SETTLE_TOL = 1e-11
"""Relative change per sample below which a trajectory under a constant force has settled: the rest
of the record is its last state (the modes decay geometrically, so the change still to come is at
most ~30x the last one at the slowest decay of the membrane, 30 ms)."""

SETTLE_TOL_TANGENT = 1e-7
"""The same for the tangents: a Jacobian needs far fewer digits than the residuals (an error of
1e-7 moves a Levenberg–Marquardt step by as little, and the band not at all); on a 1 s record it
settles ~0.3 s earlier (the slowest decay, 30 ms, takes 0.28 s for the four decades)."""


@njit(cache=True)
def _converged(new, old, rate, tol):
    """Both the change from ``old`` to ``new`` and ``rate`` (its velocity times the sample period)
    are below ``tol`` times the size of ``new``."""
    scale = 0.0
    diff = 0.0
    for i in range(new.size):
        scale = max(scale, abs(new.flat[i]))
        diff = max(diff, abs(new.flat[i] - old.flat[i]), abs(rate.flat[i]))
    return diff <= tol * scale


@njit(cache=True)
def _trajectory_buffers(m, r):
    return (
        np.empty((r, r)), np.empty(m), np.empty(m), np.empty(m), np.empty(m),
        np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m),
    )  # fmt: skip


@njit(cache=True)
def _trajectory_sample(q, v, u, k0, a, e, h, substeps, r, Tc, b):
    """``substeps`` predictor-corrector sub-steps of the state alone (buffers ``b`` of
    :func:`_trajectory_buffers`); returns the new ``q, v`` (buffers swapped, not copied)."""
    S, k1, R1, k2, R2, qp, vp, uu, km, qn, vn = b
    m = q.size
    for _ in range(substeps):
        _stiff(q, k0, r, Tc, S, k1, R1)
        for j in range(r):
            uu[j] = u[j] - R1[j]
        _oscillate(q, v, uu, k1, a, e, h, qp, vp, r)  # only the cubic modes' prediction is used
        _stiff(qp, k0, r, Tc, S, k2, R2)
        for j in range(m):
            uu[j] = u[j] - 0.5 * (R1[j] + R2[j])
            km[j] = 0.5 * (k1[j] + k2[j])
        _oscillate(q, v, uu, km, a, e, h, qn, vn, m)
        q, qn = qn, q
        v, vn = vn, v
    b = (S, k1, R1, k2, R2, qp, vp, uu, km, qn, vn)
    return q, v, b


@njit(cache=True)
def fvk_trajectory(q0, v0, forces, k0, a, e, h, substeps, r, Tc, settle, tol):
    """Modal displacements ``(N + 1, m)`` of one real trajectory (forces ``(N, m)`` held per sample;
    from interval ``settle`` on the force is constant and the loop stops once the state settles)."""
    N, m = forces.shape
    Q = np.empty((N + 1, m))
    Q[0] = q0
    _continue(Q, q0.copy(), v0.copy(), forces, 0, k0, a, e, h, substeps, r, Tc, settle, tol)
    return Q


@njit(cache=True)
def _continue(Q, q, v, forces, n0, k0, a, e, h, substeps, r, Tc, settle, tol):
    """Fill ``Q[n0 + 1:]`` from the state ``q, v`` at sample ``n0``, stopping once settled."""
    N = forces.shape[0]
    b = _trajectory_buffers(q.size, r)
    for n in range(n0, N):
        q, v, b = _trajectory_sample(q, v, forces[n], k0, a, e, h, substeps, r, Tc, b)
        Q[n + 1] = q
        if n >= settle and _converged(Q[n + 1], Q[n], v * (h * substeps), tol):
            for j in range(n + 2, N + 1):
                Q[j] = q
            break


@njit(cache=True)
def _stiff_tangent(q, dq, k0, dk0, r, Tc, Bd, S, kk, R, dk, dR):
    """:func:`_stiff` and, on the cubic modes, its tangent along the directions ``dq`` (``(m, P)``,
    mode-major so that the loops over directions are contiguous): ``dk, dR`` are ``(r, P)`` (the
    linear modes' stiffness tangent is ``dk0``, their cubic force zero)."""
    _stiff(q, k0, r, Tc, S, kk, R)
    P = dq.shape[1]
    W = np.zeros((r, r))  # W[i, k] = B_iikl x_l
    for i in range(r):
        for k in range(r):
            acc = 0.0
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


@njit(cache=True)
def _coefficients(k, a, e, h, out):
    """The step coefficients and their partials w.r.t. ``k`` and ``a`` (``tangent.step_gains``) into ``out`` (12,)."""
    hh = h * h
    zz = (k - a * a) * hh
    CZ, SZ = _cs(zz)
    s = SZ * h
    es = e * s
    dSZ = (CZ - SZ) / (2.0 * zz)
    CZk = -0.5 * SZ * hh
    esk = e * h * dSZ * hh
    za = -2.0 * a * hh
    ea = -h * e
    CZa = -0.5 * SZ * za
    esa = ea * s + e * h * dSZ * za
    out[0] = e * CZ + a * es  # A
    out[1] = es
    out[2] = e * CZ - a * es  # Cq
    out[3] = k * es  # Dk
    out[4] = e * CZk + a * esk  # Ak
    out[5] = esk
    out[6] = e * CZk - a * esk  # Cqk
    out[7] = es + k * esk  # Dkk
    out[8] = ea * CZ + e * CZa + es + a * esa  # Aa
    out[9] = esa
    out[10] = ea * CZ + e * CZa - es - a * esa  # Cqa
    out[11] = k * esa  # Dka


@njit(cache=True)
def _oscillate_tangent(q, v, u, k, a, e, h, dq, dv, du, dk, da, q1, v1, dq1, dv1, stop, r, table, dk0, du_c, dk_c):
    """:func:`_oscillate` and its tangent for the modes ``< stop``. The cubic modes (``< r``) take
    their force and stiffness tangents from ``du_c, dk_c`` ``(r, P)``; the others have the constant
    stiffness ``k0`` (coefficients in ``table``, computed once), tangent ``dk0``, force tangent ``du``."""
    P = dq.shape[1]
    c = np.empty(12)
    for j in range(stop):
        if j >= r:
            c[:] = table[j - r]
            duj, dkj = du[j], dk0[j]
        else:
            _coefficients(k[j], a[j], e[j], h, c)
            duj, dkj = du_c[j], dk_c[j]
        A, es, Cq, Dk = c[0], c[1], c[2], c[3]
        Ak, esk, Cqk, Dkk = c[4], c[5], c[6], c[7]
        Aa, esa, Cqa, Dka = c[8], c[9], c[10], c[11]
        qe = u[j] / k[j]
        x = q[j] - qe
        q1[j] = qe + A * x + es * v[j]
        v1[j] = Cq * v[j] - Dk * x
        gq = Ak * x + esk * v[j]
        gv = Cqk * v[j] - Dkk * x
        hq = Aa * x + esa * v[j]
        hv = Cqa * v[j] - Dka * x
        ik = 1.0 / k[j]
        dqj, dvj, daj, dq1j, dv1j = dq[j], dv[j], da[j], dq1[j], dv1[j]
        for p in range(P):
            dqe = (duj[p] - qe * dkj[p]) * ik
            dx = dqj[p] - dqe
            dq1j[p] = dqe + A * dx + es * dvj[p] + gq * dkj[p] + hq * daj[p]
            dv1j[p] = Cq * dvj[p] - Dk * dx + gv * dkj[p] + hv * daj[p]


@njit(cache=True)
def _substep_tangent(q, v, dq, dv, u, du, k0, dk0, a, da, e, h, r, Tc, Bd, table, w, qn, vn, dqn, dvn):
    """One predictor-corrector sub-step of the state and its tangent into ``qn, vn, dqn, dvn``
    (``w``: the work arrays of :func:`_work`)."""
    S, k1, R1, k2, R2, uu, km, qp, vp, dk1, dR1, dk2, dR2, du_c, dk_c, dqp, dvp = w
    m, P = dq.shape
    # predictor: the cubic modes only (the linear modes' stiffness does not move)
    _stiff_tangent(q, dq, k0, dk0, r, Tc, Bd, S, k1, R1, dk1, dR1)
    for j in range(m):
        uu[j] = u[j] - R1[j]
    for i in range(r):
        for p in range(P):
            du_c[i, p] = du[i, p] - dR1[i, p]
    _oscillate_tangent(q, v, uu, k1, a, e, h, dq, dv, du, dk1, da, qp, vp, dqp, dvp, r, r, table, dk0, du_c, dk1)
    # corrector: the mean of the start and predicted-end stiffness and cubic force
    _stiff_tangent(qp, dqp, k0, dk0, r, Tc, Bd, S, k2, R2, dk2, dR2)
    for j in range(m):
        uu[j] = u[j] - 0.5 * (R1[j] + R2[j])
        km[j] = 0.5 * (k1[j] + k2[j])
    for i in range(r):
        for p in range(P):
            du_c[i, p] = du[i, p] - 0.5 * (dR1[i, p] + dR2[i, p])
            dk_c[i, p] = 0.5 * (dk1[i, p] + dk2[i, p])
    _oscillate_tangent(q, v, uu, km, a, e, h, dq, dv, du, dk_c, da, qn, vn, dqn, dvn, m, r, table, dk0, du_c, dk_c)


@njit(cache=True)
def _work(m, P, r):
    """Work arrays of :func:`_substep_tangent`."""
    return (
        np.empty((r, r)), np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m),
        np.empty(m), np.empty(m), np.empty((r, P)), np.empty((r, P)), np.empty((r, P)), np.empty((r, P)),
        np.empty((r, P)), np.empty((r, P)), np.empty((m, P)), np.empty((m, P)),
    )  # fmt: skip


@njit(cache=True)
def _linear_table(k0, a, e, h, r):
    """Step coefficients of the linear modes (``>= r``), which keep the stiffness ``k0``."""
    m = k0.size
    table = np.empty((m - r, 12))
    for j in range(r, m):
        _coefficients(k0[j], a[j], e[j], h, table[j - r])
    return table


@njit(cache=True)
def fvk_step_tangent(q, v, u, du, k0, dk0, a, da, e, h, substeps, r, Tc, Bd, dq, dv):
    """One sample (``substeps`` sub-steps, force ``u`` held, its tangent ``du`` ``(m, P)``) of the
    state and its tangent (mode-major ``(m, P)``): ``q1, v1, dq1, dv1`` (the inputs are kept)."""
    m, P = dq.shape
    w = _work(m, P, r)
    table = _linear_table(k0, a, e, h, r)
    state = (q.copy(), v.copy(), dq.copy(), dv.copy(), np.empty(m), np.empty(m), np.empty((m, P)), np.empty((m, P)))
    q, v, dq, dv, _, _, _, _ = _sample(state, u, du, k0, dk0, a, da, e, h, substeps, r, Tc, Bd, table, w)
    return q, v, dq, dv


@njit(cache=True)
def _sample(state, u, du, k0, dk0, a, da, e, h, substeps, r, Tc, Bd, table, w):
    """``substeps`` sub-steps of ``state = (q, v, dq, dv, qn, vn, dqn, dvn)`` (the last four: spare
    buffers); returns the state with the result first (buffers swapped, not copied)."""
    q, v, dq, dv, qn, vn, dqn, dvn = state
    for _ in range(substeps):
        _substep_tangent(q, v, dq, dv, u, du, k0, dk0, a, da, e, h, r, Tc, Bd, table, w, qn, vn, dqn, dvn)
        q, qn = qn, q
        v, vn = vn, v
        dq, dqn = dqn, dq
        dv, dvn = dvn, dv
    return q, v, dq, dv, qn, vn, dqn, dvn


@njit(cache=True)
def fvk_tangent(
    q0, v0, forces, k0, dk0, a, da, e, h, substeps, r, Tc, Bd, dq0, dv0, amp, dforce, hats, g0, fc, settle, tol,
    tol_tangent,
):  # fmt: skip
    """Trajectory ``(N+1, m)`` and its tangents ``(N+1, m, P)`` (tangent arrays mode-major:
    ``dk0, da, dq0, dv0, dforce`` are ``(m, P)``).

    The force tangent over interval ``n`` is ``amp[n] * dforce`` plus ``hats[n, g] * fc`` in the
    columns ``g0 + g`` of the gust knots (``hats`` may have no columns). From interval ``settle``
    on force and tangent are constant: once the tangent has settled to ``tol_tangent`` it is held
    (a Jacobian needs no more digits) and the state alone goes on until it settles to ``tol``.
    """
    N, m = forces.shape
    P = dq0.shape[1]
    Q = np.empty((N + 1, m))
    dQ = np.empty((N + 1, m, P))
    state = (q0.copy(), v0.copy(), dq0.copy(), dv0.copy(), np.empty(m), np.empty(m), np.empty((m, P)), np.empty((m, P)))
    w = _work(m, P, r)
    du = np.empty((m, P))
    table = _linear_table(k0, a, e, h, r)
    ng = hats.shape[1]
    dt = h * substeps
    Q[0], dQ[0] = q0, dq0
    for n in range(N):
        u = forces[n]
        an = amp[n]
        for j in range(m):
            duj, dfj = du[j], dforce[j]
            for p in range(P):
                duj[p] = an * dfj[p]
            for g in range(ng):
                duj[g0 + g] += hats[n, g] * fc[j]
        state = _sample(state, u, du, k0, dk0, a, da, e, h, substeps, r, Tc, Bd, table, w)
        q, v, dq, dv = state[0], state[1], state[2], state[3]
        Q[n + 1] = q
        dQ[n + 1] = dq
        if n >= settle and _converged(dQ[n + 1], dQ[n], dv * dt, tol_tangent):
            for j in range(n + 2, N + 1):
                dQ[j] = dq
            if not _converged(Q[n + 1], Q[n], v * dt, tol):
                _continue(Q, q.copy(), v.copy(), forces, n + 1, k0, a, e, h, substeps, r, Tc, settle, tol)
            else:
                for j in range(n + 2, N + 1):
                    Q[j] = q
            break
    return Q, dQ
