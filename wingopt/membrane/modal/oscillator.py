"""The exact step of one damped modal oscillator, its tangent, and the linear part of a sub-step.

Every modal membrane (:mod:`wingopt.membrane.modal`) integrates ``q'' + c q' + k q = u`` mode by
mode with the exact solution for ``k``, ``c``, ``u`` held over a step; the nonlinear models update
``k`` (and a force) between the stages of a predictor-corrector. The solution is written with the
entire functions ``cos(sqrt(z))`` and ``sin(sqrt(z))/sqrt(z)`` of ``z = (k - c^2/4) h^2``, so it is
analytic in every argument (under- and over-damped alike) and complex-step differentiation is exact.

For ``q1, v1 = step(q, v, u, k, a)`` (``a = c/2``, ``zz = (k - a^2) h^2``, ``CZ = cos(sqrt zz)``,
``SZ = sin(sqrt zz)/sqrt zz``): ``dCZ/dzz = -SZ/2``, ``dSZ/dzz = (CZ - SZ) / (2 zz)``,
``de/da = -h e``; :func:`oscillator_tangent` propagates ``P`` directions through one step with the
transcendental functions evaluated once per mode.
"""

from __future__ import annotations

import numpy as np

__all__ = ["oscillator_step", "oscillator_tangent", "step_gains", "prestress_terms"]


def _cos_sinc(zz):
    """``cos(sqrt(zz))`` and ``sin(sqrt(zz))/sqrt(zz)`` (entire functions of ``zz``; ``zz != 0``)."""
    r = np.sqrt(zz + 0j)
    c, s = np.cos(r), np.sin(r) / r
    if not np.iscomplexobj(zz):
        return c.real, s.real
    return c, s


def oscillator_step(q, v, u, k, c, h, e=None):
    """Exact state after ``h`` of ``q'' + c q' + k q = u`` (all held constant), element-wise.

    ``e = exp(-c h / 2)`` may be passed when it is the same for many steps.
    """
    a = 0.5 * c
    cz, sz = _cos_sinc((k - a * a) * (h * h))
    e = np.exp(-a * h) if e is None else e
    s = sz * h  # sin(wd h) / wd
    qe = u / k
    dq = q - qe
    es = e * s
    q1 = qe + (e * cz + a * es) * dq + es * v
    v1 = (e * cz - a * es) * v - (k * es) * dq
    return q1, v1


def step_gains(k, a, e, h, velocity: bool = True):
    """Coefficients of one exact oscillator step and their partials w.r.t. ``k`` and ``a`` (all
    ``(m,)``): ``A, es, Ak, esk, Aa, esa`` of the displacement and, with ``velocity``, ``Cq, Dk,
    Cqk, Dkk, Cqa, Dka`` of the velocity (the predictor needs the displacement's only). Shared by
    the record tangent and the streaming one-sample tangent
    (:class:`~wingopt.membrane.modal.berger_step.BergerSample`)."""
    zz = (k - a * a) * (h * h)
    if zz.min() > 0:  # all modes under-damped (the usual case): no branch to select
        r = np.sqrt(zz)
        CZ, SZ = np.cos(r), np.sin(r) / r
    else:
        pos = zz > 0
        r = np.sqrt(np.abs(zz))
        CZ = np.where(pos, np.cos(r), np.cosh(r))
        SZ = np.where(pos, np.sin(r), np.sinh(r)) / r
    s = SZ * h
    es = e * s
    A = e * CZ + a * es
    dSZ = (CZ - SZ) / (2 * zz)
    # partials w.r.t. k (zz_k = h^2)
    CZk = -0.5 * SZ * h * h
    esk = e * h * dSZ * h * h
    Ak = e * CZk + a * esk
    # partials w.r.t. a (zz_a = -2 a h^2, e_a = -h e)
    za = -2 * a * h * h
    ea = -h * e
    CZa = -0.5 * SZ * za
    esa = ea * s + e * h * dSZ * za
    Aa = ea * CZ + e * CZa + es + a * esa
    if not velocity:
        return A, es, Ak, esk, Aa, esa
    Cq = e * CZ - a * es
    Cqk = e * CZk - a * esk
    Cqa = ea * CZ + e * CZa - es - a * esa
    return A, es, Ak, esk, Aa, esa, Cq, k * es, Cqk, es + k * esk, Cqa, k * esa


def oscillator_tangent(q, v, u, k, a, e, h, dq, dv, du, dk, da):
    """One exact oscillator step and its tangent for directions ``(P, m)`` (``a = c/2``, ``e = exp(-a h)``;
    ``dq, dv, du, dk, da`` the directions of the state, force, stiffness and half damping)."""
    A, B, Ak, Bk, Aa, Ba, Cq, Dk, Cqk, Dkk, Cqa, Dka = step_gains(k, a, e, h)
    qe = u / k
    x = q - qe
    q1 = qe + A * x + B * v
    v1 = Cq * v - Dk * x
    dqe = (du - qe * dk) / k
    dx = dq - dqe
    dq1 = dqe + A * dx + B * dv + (Ak * x + Bk * v) * dk + (Aa * x + Ba * v) * da
    dv1 = Cq * dv - Dk * dx + (Cqk * v - Dkk * x) * dk + (Cqa * v - Dka * x) * da
    return q1, v1, dq1, dv1


def prestress_terms(bm, ex, ey, damping, dpar, substeps: int | None = None):
    """The parameter-dependent linear part of a sub-step and its tangents.

    Returns ``h`` (sub-step), the prestress stiffness ``k0`` and its tangent ``dk0`` (P, m), half
    the damping ``a`` and ``da`` (P, m), and ``e = exp(-a h)``; ``dpar`` is ``(3, P)``, the seeds of
    ``ex, ey, damping``; ``substeps`` per sample (default the model's). Shared by the Berger and the
    cubic FvK models (same linear part).
    """
    mat = bm.model.problem.material
    nu, C, h = mat.poisson_ratio, bm.stiffness_c, bm.dt / (bm.substeps if substeps is None else substeps)
    k0 = C * ((ex + nu * ey) * bm.kx + (ey + nu * ex) * bm.ky)
    k0x, k0y = C * (bm.kx + nu * bm.ky), C * (bm.ky + nu * bm.kx)
    visc = mat.viscous / mat.areal_density + mat.kelvin_voigt * k0
    a = 0.5 * damping * visc
    dex, dey, dd = dpar
    dk0 = np.outer(dex, k0x) + np.outer(dey, k0y)
    da = 0.5 * (np.outer(dd, visc) + damping * mat.kelvin_voigt * dk0)
    return h, k0, dk0, a, da, np.exp(-a * h)
