"""The one time loop of every modal membrane: a record, its exact tangent, one sample (compiled).

Each mode is the damped oscillator ``q'' + 2a q' + k q = u``; over a sub-step ``h`` with ``k``,
``a``, ``u`` held it is solved exactly (:func:`_gains`, the one solution of the linear modal
equation), written with the entire functions ``cos(sqrt zz)`` and ``sin(sqrt zz)/sqrt zz`` of
``zz = (k - a^2) h^2`` so that it is analytic in every argument (under- and over-damped alike;
complex arguments run the same loop, and complex steps differentiate it exactly). The nonlinear
models update ``k`` and a force between the stages of a predictor-corrector: the force law
(:mod:`.laws`, Berger or FvK) at the step start, the oscillators stepped to a predicted end, the
law's mean of start and predicted end for the corrector step. Second order in the stiffness
variation, exact for the linear membrane.

The predictor-corrector sub-step is written once (:func:`_substep`): the state and its tangent along
``P`` directions (mode-major ``(m, P)``; ``P = 0``: the state alone), the transcendental functions
evaluated once per mode and stage and the directions propagated by multiply-adds.
:func:`trajectory` integrates a record (real or complex), :func:`tangent` a record and its exact
tangent (:func:`trajectory_substeps`, :func:`tangent_substeps`: at every sub-step, with the modal
velocities and theirs, for a DAQ filter run on the outputs' interpolant), :func:`step_tangent`
one sample with the velocity tangents too (the streaming filter). For
``q1, v1 = step(q, v, u, k, a)``: ``dCZ/dzz = -SZ/2``, ``dSZ/dzz = (CZ - SZ) / (2 zz)``,
``de/da = -h e``. Why compiled: one sample is ~100 small array operations in NumPy, so a 1 s
record at 1 kHz costs ~0.5 s per Jacobian in interpreter overhead alone; here it costs the arithmetic.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numba.core import types
from numba.extending import overload

from wingopt.membrane.modal.laws import stiffness_tangent
from wingopt.membrane.modal.tangent import settled_from  # the kernels' settle index, here as before

__all__ = [
    "SETTLE_TOL",
    "SETTLE_TOL_TANGENT",
    "settled_from",
    "trajectory",
    "trajectory_substeps",
    "tangent",
    "tangent_substeps",
    "step_tangent",
]

SETTLE_TOL = 1e-11
"""Relative change per sample below which a trajectory under a constant force has settled: the rest
of the record is its last state (the modes decay geometrically, so the change still to come is at
most ~30x the last one at the slowest decay of the membrane, 30 ms)."""

SETTLE_TOL_TANGENT = 1e-7
"""The same for the tangents: a Jacobian needs far fewer digits than the residuals (an error of
1e-7 moves a Levenberg–Marquardt step by as little, and the band not at all); on a 1 s record it
settles ~0.3 s earlier (the slowest decay, 30 ms, takes 0.28 s for the four decades)."""


def _cs(zz):  # pragma: no cover - compiled through the overload below
    """``cos(sqrt zz)`` and ``sin(sqrt zz)/sqrt zz`` (entire functions of ``zz``; ``zz != 0``)."""


@overload(_cs)
def _cs_typed(zz):
    if isinstance(zz, types.Complex):

        def complex_(zz):
            rr = np.sqrt(zz)
            return np.cos(rr), np.sin(rr) / rr

        return complex_

    def real(zz):  # cosh/sinh below zero (over-damped modes), no complex arithmetic
        if zz > 0:
            rr = np.sqrt(zz)
            return np.cos(rr), np.sin(rr) / rr
        rr = np.sqrt(-zz)
        return np.cosh(rr), np.sinh(rr) / rr

    return real


@njit(cache=True)
def _gains(k, a, e, h):
    """The exact step ``q1 = qe + A (q - qe) + es v``, ``v1 = Cq v - Dk (q - qe)`` (``qe = u / k``):
    returns ``zz, CZ, SZ, s = SZ h, es, A, Cq, Dk``."""
    zz = (k - a * a) * (h * h)
    CZ, SZ = _cs(zz)
    s = SZ * h
    es = e * s
    return zz, CZ, SZ, s, es, e * CZ + a * es, e * CZ - a * es, k * es


@njit(cache=True)
def _coefficients(k, a, e, h, out):
    """:func:`_gains` and their partials w.r.t. ``k`` and ``a`` into ``out`` (12,)."""
    zz, CZ, SZ, s, es, A, Cq, Dk = _gains(k, a, e, h)
    hh = h * h
    dSZ = (CZ - SZ) / (2.0 * zz)
    CZk = -0.5 * SZ * hh  # zz_k = h^2
    esk = e * h * dSZ * hh
    za = -2.0 * a * hh  # zz_a = -2 a h^2, e_a = -h e
    ea = -h * e
    CZa = -0.5 * SZ * za
    esa = ea * s + e * h * dSZ * za
    out[0], out[1], out[2], out[3] = A, es, Cq, Dk
    out[4] = e * CZk + a * esk  # Ak
    out[5] = esk
    out[6] = e * CZk - a * esk  # Cqk
    out[7] = es + k * esk  # Dkk
    out[8] = ea * CZ + e * CZa + es + a * esa  # Aa
    out[9] = esa
    out[10] = ea * CZ + e * CZa - es - a * esa  # Cqa
    out[11] = k * esa  # Dka


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


# -- the one sub-step ----------------------------------------------------------------------------
@njit(cache=True)
def _oscillate(q, v, u, k, a, e, h, dq, dv, du, dk, da, q1, v1, dq1, dv1, stop, r, table, dk0, du_c, dk_c, c):
    """Exact step of the modes ``< stop`` into ``q1, v1`` and its tangent (``P = dq.shape[1]``
    directions, none at ``P = 0``). The moving modes (``< r``) take their force and stiffness
    tangents from ``du_c, dk_c`` ``(r, P)``; the others have the constant stiffness ``k0``
    (coefficients in ``table``, computed once), tangent ``dk0``, force tangent ``du``."""
    P = dq.shape[1]
    for j in range(stop):
        if j >= r:
            c[:] = table[j - r]
        elif P == 0:
            g = _gains(k[j], a[j], e[j], h)
            c[0], c[1], c[2], c[3] = g[5], g[4], g[6], g[7]
        else:
            _coefficients(k[j], a[j], e[j], h, c)
        A, es, Cq, Dk = c[0], c[1], c[2], c[3]
        qe = u[j] / k[j]
        x = q[j] - qe
        q1[j] = qe + A * x + es * v[j]
        v1[j] = Cq * v[j] - Dk * x
        if P == 0:
            continue
        duj, dkj = (du[j], dk0[j]) if j >= r else (du_c[j], dk_c[j])
        Ak, esk, Cqk, Dkk = c[4], c[5], c[6], c[7]
        Aa, esa, Cqa, Dka = c[8], c[9], c[10], c[11]
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
def _substep(q, v, dq, dv, u, du, k0, dk0, a, da, e, h, law, table, w, qn, vn, dqn, dvn):
    """One predictor-corrector sub-step of the state and its tangent into ``qn, vn, dqn, dvn``
    (``w``: the work arrays of :func:`_work`): the force law at the step start, the moving modes
    stepped to a predicted end (the others' stiffness does not move), the law's mean of the two
    for the corrector step of every mode."""
    S, k1, R1, k2, R2, uu, km, qp, vp, dk1, dR1, dk2, dR2, du_c, dk_c, dqp, dvp, c = w
    m, P = dq.shape
    r = law[1]
    stiffness_tangent(law, q, dq, k0, dk0, S, k1, R1, dk1, dR1)
    for j in range(m):
        uu[j] = u[j] - R1[j]
    for i in range(r):
        for p in range(P):
            du_c[i, p] = du[i, p] - dR1[i, p]
    _oscillate(q, v, uu, k1, a, e, h, dq, dv, du, dk1, da, qp, vp, dqp, dvp, r, r, table, dk0, du_c, dk1, c)
    stiffness_tangent(law, qp, dqp, k0, dk0, S, k2, R2, dk2, dR2)
    for j in range(m):
        uu[j] = u[j] - 0.5 * (R1[j] + R2[j])
        km[j] = 0.5 * (k1[j] + k2[j])
    for i in range(r):
        for p in range(P):
            du_c[i, p] = du[i, p] - 0.5 * (dR1[i, p] + dR2[i, p])
            dk_c[i, p] = 0.5 * (dk1[i, p] + dk2[i, p])
    _oscillate(q, v, uu, km, a, e, h, dq, dv, du, dk_c, da, qn, vn, dqn, dvn, m, r, table, dk0, du_c, dk_c, c)


@njit(cache=True)
def _work(q, P, law):
    """Work arrays of :func:`_substep` (in ``q``'s dtype)."""
    m, r, rs, t = q.size, law[1], law[3].shape[0], q.dtype
    return (
        np.empty((rs, rs), t),
        np.empty(m, t),
        np.empty(m, t),
        np.empty(m, t),
        np.empty(m, t),
        np.empty(m, t),
        np.empty(m, t),
        np.empty(m, t),
        np.empty(m, t),
        np.empty((r, P), t),
        np.empty((r, P), t),
        np.empty((r, P), t),
        np.empty((r, P), t),
        np.empty((r, P), t),
        np.empty((r, P), t),
        np.empty((m, P), t),
        np.empty((m, P), t),
        np.empty(12, t),
    )


@njit(cache=True)
def _linear_table(k0, a, e, h, r):
    """Step coefficients of the modes ``>= r``, which keep the stiffness ``k0``."""
    m = k0.size
    table = np.empty((m - r, 12), k0.dtype)
    for j in range(r, m):
        _coefficients(k0[j], a[j], e[j], h, table[j - r])
    return table


@njit(cache=True)
def _advance(state, u, du, k0, dk0, a, da, e, h, substeps, law, table, w):
    """``substeps`` sub-steps of ``state = (q, v, dq, dv, qn, vn, dqn, dvn)`` (the last four: spare
    buffers); returns the state with the result first (buffers swapped, not copied)."""
    q, v, dq, dv, qn, vn, dqn, dvn = state
    for _ in range(substeps):
        _substep(q, v, dq, dv, u, du, k0, dk0, a, da, e, h, law, table, w, qn, vn, dqn, dvn)
        q, qn = qn, q
        v, vn = vn, v
        dq, dqn = dqn, dq
        dv, dvn = dvn, dv
    return q, v, dq, dv, qn, vn, dqn, dvn


@njit(cache=True)
def _state(q, v, dq, dv):
    """A state of :func:`_advance` (copies) with its spare buffers."""
    spare = (np.empty_like(q), np.empty_like(v), np.empty_like(dq), np.empty_like(dv))
    return (q.copy(), v.copy(), dq.copy(), dv.copy()) + spare


# -- the entry points ---------------------------------------------------------------------------
@njit(cache=True)
def trajectory(q0, v0, forces, k0, a, e, h, substeps, law, settle, tol):
    """Modal displacements ``(N + 1, m)`` of one trajectory (forces ``(N, m)`` held per sample; from
    interval ``settle`` on the force is constant and the loop stops once the state settles)."""
    N, m = forces.shape
    Q = np.empty((N + 1, m), q0.dtype)
    Q[0] = q0
    none = np.empty((0, m), q0.dtype)  # not at the sub-steps, no velocities
    _continue(Q, none, q0, v0, forces, 0, k0, a, e, h, substeps, law, _linear_table(k0, a, e, h, law[1]), settle, tol)
    return Q


@njit(cache=True)
def trajectory_substeps(q0, v0, forces, k0, a, e, h, substeps, law, settle, tol):
    """:func:`trajectory` at every sub-step (sample ``n`` at row ``n substeps``), the modal
    velocities ``(N substeps + 1, m)`` beside it (a settled record holds its last state)."""
    N, m = forces.shape
    Q, V = np.empty((N * substeps + 1, m), q0.dtype), np.empty((N * substeps + 1, m), q0.dtype)
    Q[0], V[0] = q0, v0
    _continue(Q, V, q0, v0, forces, 0, k0, a, e, h, substeps, law, _linear_table(k0, a, e, h, law[1]), settle, tol)
    return Q, V


@njit(cache=True)
def _samples(state, u, du, k0, dk0, a, da, e, h, substeps, law, table, w, n, Q, dQ, V, dV):
    """One sample on from sample ``n``, into row ``n + 1`` of ``Q`` (and ``dQ`` when it has
    directions), or, where ``V`` has rows, every sub-step's state into the rows ``n substeps + s``
    of ``Q, V, dQ, dV``; returns the state and the rows of samples ``n + 1`` and ``n``."""
    if V.shape[0] == 0:
        state = _advance(state, u, du, k0, dk0, a, da, e, h, substeps, law, table, w)
        Q[n + 1] = state[0]
        if dQ.shape[0]:
            dQ[n + 1] = state[2]
        return state, n + 1, n
    for s in range(1, substeps + 1):  # one sub-step at a time: the same arithmetic
        state = _advance(state, u, du, k0, dk0, a, da, e, h, 1, law, table, w)
        i = n * substeps + s
        Q[i], V[i] = state[0], state[1]
        if dQ.shape[0]:
            dQ[i], dV[i] = state[2], state[3]
    return state, (n + 1) * substeps, n * substeps


@njit(cache=True)
def _continue(Q, V, q, v, forces, n0, k0, a, e, h, substeps, law, table, settle, tol):
    """Fill ``Q`` (and ``V``: :func:`_samples`) after sample ``n0`` with the state alone from
    ``q, v`` there, stopping once settled."""
    N, m = forces.shape
    none = np.empty((m, 0), q.dtype)  # no tangent directions
    state = _state(q, v, none, none)
    w = _work(q, 0, law)
    nothing = np.empty((0, m, 0), q.dtype)
    for n in range(n0, N):
        state, i1, i0 = _samples(
            state, forces[n], none, k0, none, a, none, e, h, substeps, law, table, w, n, Q, nothing, V, nothing
        )
        if n >= settle and _converged(Q[i1], Q[i0], state[1] * (h * substeps), tol):
            _hold(Q, V, i1, state[0], state[1])
            break


@njit(cache=True)
def _hold(X, Y, i, x, y):
    """The rows after ``i`` of ``X`` (and of ``Y`` when it has rows) hold ``x`` (``y``): settled."""
    for j in range(i + 1, X.shape[0]):
        X[j] = x
        if Y.shape[0]:
            Y[j] = y


@njit(cache=True)
def step_tangent(q, v, u, du, k0, dk0, a, da, e, h, substeps, law, dq, dv):
    """One sample (``substeps`` sub-steps, force ``u`` held, its tangent ``du`` ``(m, P)``) of the
    state and its tangent (mode-major ``(m, P)``): ``q1, v1, dq1, dv1`` (the inputs are kept)."""
    w = _work(q, dq.shape[1], law)
    table = _linear_table(k0, a, e, h, law[1])
    q, v, dq, dv, _, _, _, _ = _advance(_state(q, v, dq, dv), u, du, k0, dk0, a, da, e, h, substeps, law, table, w)
    return q, v, dq, dv


@njit(cache=True)
def tangent(q0, v0, forces, k0, dk0, a, da, e, h, substeps, law, dq0, dv0, amp, dforce, hats, g0, fc, settle, tols):
    """Trajectory ``(N+1, m)`` and its tangents ``(N+1, m, P)`` (tangent arrays mode-major:
    ``dk0, da, dq0, dv0, dforce`` are ``(m, P)``).

    The force tangent over interval ``n`` is ``amp[n] * dforce`` plus ``hats[n, g] * fc`` in the
    columns ``g0 + g`` of the gust knots (``hats`` may have no columns). From interval ``settle``
    on force and tangent are constant: once the tangent has settled to ``tols[1]`` it is held (a
    Jacobian needs no more digits) and the state alone goes on until it settles to ``tols[0]``.
    """
    N, m = forces.shape
    P = dq0.shape[1]
    Q, dQ = np.empty((N + 1, m)), np.empty((N + 1, m, P))
    V, dV = np.empty((0, m)), np.empty((0, m, P))  # not at the sub-steps, no velocities
    force = (amp, dforce, hats, g0, fc)
    _record_tangent(Q, dQ, V, dV, q0, v0, forces, k0, dk0, a, da, e, h, substeps, law, dq0, dv0, force, settle, tols)
    return Q, dQ


@njit(cache=True)
def tangent_substeps(
    q0, v0, forces, k0, dk0, a, da, e, h, substeps, law, dq0, dv0, amp, dforce, hats, g0, fc, settle, tols
):
    """:func:`tangent` at every sub-step (sample ``n`` at row ``n substeps``) with the modal
    velocities ``(N substeps + 1, m)`` and their tangents (held, as the displacements', once settled)."""
    N, m = forces.shape
    n, P = N * substeps + 1, dq0.shape[1]
    Q, dQ, V, dV = np.empty((n, m)), np.empty((n, m, P)), np.empty((n, m)), np.empty((n, m, P))
    force = (amp, dforce, hats, g0, fc)
    _record_tangent(Q, dQ, V, dV, q0, v0, forces, k0, dk0, a, da, e, h, substeps, law, dq0, dv0, force, settle, tols)
    return Q, dQ, V, dV


@njit(cache=True)
def _record_tangent(Q, dQ, V, dV, q0, v0, forces, k0, dk0, a, da, e, h, substeps, law, dq0, dv0, force, settle, tols):
    """The loop of :func:`tangent` into ``Q, dQ`` (and ``V, dV``: :func:`_samples`); ``force``:
    ``(amp, dforce, hats, g0, fc)``."""
    amp, dforce, hats, g0, fc = force
    N, m = forces.shape
    P = dq0.shape[1]
    state = _state(q0, v0, dq0, dv0)
    w = _work(q0, P, law)
    du = np.empty((m, P))
    table = _linear_table(k0, a, e, h, law[1])
    ng = hats.shape[1]
    dt = h * substeps
    Q[0], dQ[0] = q0, dq0
    if V.shape[0]:
        V[0], dV[0] = v0, dv0
    for n in range(N):
        an = amp[n]
        for j in range(m):
            duj, dfj = du[j], dforce[j]
            for p in range(P):
                duj[p] = an * dfj[p]
            for g in range(ng):
                duj[g0 + g] += hats[n, g] * fc[j]
        state, i1, i0 = _samples(state, forces[n], du, k0, dk0, a, da, e, h, substeps, law, table, w, n, Q, dQ, V, dV)
        q, v, dq, dv = state[0], state[1], state[2], state[3]
        if n >= settle and _converged(dQ[i1], dQ[i0], dv * dt, tols[1]):
            _hold(dQ, dV, i1, dq, dv)
            if not _converged(Q[i1], Q[i0], v * dt, tols[0]):
                _continue(Q, V, q, v, forces, n + 1, k0, a, e, h, substeps, law, table, settle, tols[0])
            else:
                _hold(Q, V, i1, q, v)
            break
