"""One sample of the modal Berger membrane and its exact tangent, for the streaming (EKF) estimator.

The map is :meth:`~wingopt.membrane.modal.berger.BergerModal.simulate` over one sample
(predictor-corrector tension, ``substeps`` steps): the same exact
oscillator step (:func:`~wingopt.membrane.modal.oscillator.oscillator_step`) with the
tension frozen over a sub-step. Its tangent is written out per stage (as in
:mod:`wingopt.membrane.modal.tangent`, which gives the displacement sensitivities of a whole
record; the filter also needs the velocities, and one sample at a time): for one oscillator step
``q1 = qe + A (q - qe) + B v``, ``v1 = Cq v - Dk (q - qe)`` (``qe = u / k``, ``a = c / 2``) the
partials w.r.t. ``q, v, u, k, a`` are per-mode vectors, the transcendental functions are evaluated
once per mode and stage, and the ``P`` directions are propagated by multiply-adds on ``(P, m)``
arrays. The stiffness depends on all displacements only through the two mean stretches, so its
tangent is a rank-2 product ``dQ @ [2 kx q, 2 ky q] @ [kxs; kys]``.

Directions are rows: ``dQ[j, i] = d q_i / d theta_j``. Rows ``load_rows`` are unit directions of
the load unknowns (they act through the modal force), rows ``par_rows`` those of the parameters
(through ``d ex, d ey, d damping``); the state part of every row is whatever the caller seeds.
"""

from __future__ import annotations

import numpy as np

from wingopt.errors import InputError
from wingopt.membrane.modal.berger import BergerModal
from wingopt.membrane.modal.oscillator import oscillator_step, step_gains

__all__ = ["BergerSample"]


class BergerSample:
    """One-sample map ``(q, v) -> (q', v')`` of a :class:`BergerModal` and its tangent.

    Parameters
    ----------
    bm : BergerModal
    load_forces : ndarray ``(ns, m)``
        Modal force per unit of each load unknown (its tangent seed).
    load_rows, par_rows : slice
        Rows of the direction arrays that are the load and the parameter unknowns.

    Attributes
    ----------
    nonlinear : bool
        ``False`` leaves the deflection's own stretch out (the linear membrane; tests).
    """

    def __init__(self, bm: BergerModal, load_forces: np.ndarray, load_rows: slice, par_rows: slice) -> None:
        if not isinstance(bm, BergerModal):
            raise InputError(f"BergerSample: needs a BergerModal, got {type(bm).__name__}")
        mat = bm.model.problem.material
        self.bm = bm
        self.m = bm.m
        self.h = bm.dt / bm.substeps
        self.substeps = bm.substeps
        self.nu, self.C = mat.poisson_ratio, bm.stiffness_c
        self.kx, self.ky = bm.kx, bm.ky
        self._K2 = np.column_stack([bm.kx, bm.ky])
        self.k0x = self.C * (bm.kx + self.nu * bm.ky)
        self.k0y = self.C * (bm.ky + self.nu * bm.kx)
        ia = 1.0 / (2.0 * bm.area)
        self.ks = np.vstack([self.C * ia * (bm.kx + self.nu * bm.ky), self.C * ia * (bm.ky + self.nu * bm.kx)])
        self.visc0, self.kv = mat.viscous / mat.areal_density, mat.kelvin_voigt
        self.load_forces = np.asarray(load_forces, dtype=float)
        self.load_rows, self.par_rows = load_rows, par_rows
        self.nonlinear = True

    def coefficients(self, ex: float, ey: float, damping: float):
        """Prestress stiffness ``k0``, half damping ``a`` and ``e = exp(-a h)`` per mode."""
        k0 = self.C * ((ex + self.nu * ey) * self.kx + (ey + self.nu * ex) * self.ky)
        a = 0.5 * damping * (self.visc0 + self.kv * k0)
        return k0, a, np.exp(-a * self.h)

    def _stiff(self, q, k0):
        on = 1.0 if self.nonlinear else 0.0
        return k0 + on * ((q * q) @ self._K2) @ self.ks

    def step(self, q, v, u, ex, ey, damping):
        """The state one sample later (no tangent; the reference for the tangent's tests)."""
        k0, a, e = self.coefficients(ex, ey, damping)
        c = 2.0 * a
        for _ in range(self.substeps):
            k1 = self._stiff(q, k0)
            qp, _ = oscillator_step(q, v, u, k1, c, self.h, e)
            k2 = 0.5 * (k1 + self._stiff(qp, k0))
            q, v = oscillator_step(q, v, u, k2, c, self.h, e)
        return q, v

    def step_tangent(self, q, v, u, ex, ey, damping, dQ, dV, dpar):
        """State one sample later and its tangents.

        Parameters
        ----------
        q, v, u : ``(m,)`` displacement, velocity and the modal force held over the sample
        ex, ey, damping : float
        dQ, dV : ``(P, m)`` seeds of ``q, v`` (not modified)
        dpar : ``(3, npar)`` seeds of ``(ex, ey, damping)`` for the parameter rows

        Returns
        -------
        q1, v1 : ``(m,)``; dQ1, dV1 : ``(P, m)``
        """
        k0, a, e = self.coefficients(ex, ey, damping)
        ps, ls = self.par_rows, self.load_rows
        dk0 = np.outer(dpar[0], self.k0x) + np.outer(dpar[1], self.k0y)  # (npar, m)
        visc = self.visc0 + self.kv * k0
        da = 0.5 * (np.outer(dpar[2], visc) + damping * self.kv * dk0)
        dU = self.load_forces
        on = 1.0 if self.nonlinear else 0.0
        K2 = self._K2
        h = self.h

        def stiff(q, dQ):
            k = k0 + on * ((q * q) @ K2) @ self.ks
            dK = (dQ @ (2.0 * on * q[:, None] * K2)) @ self.ks
            dK[ps] += dk0
            return k, dK

        def stage(q, v, k, dQ, dV, dK, velocity):
            g = step_gains(k, a, e, h, velocity)
            A, B, Ak, Bk, Aa, Ba = g[:6]
            qe = u / k
            x = q - qe
            q1 = qe + A * x + B * v
            gu = (1.0 - A) / k
            dQ1 = A * dQ
            dQ1 += B * dV
            dQ1 += (Ak * x + Bk * v - gu * qe) * dK
            dQ1[ls] += gu * dU
            dQ1[ps] += (Aa * x + Ba * v) * da
            if not velocity:
                return q1, None, dQ1, None
            Cq, Dk, Cqk, Dkk, Cqa, Dka = g[6:]
            v1 = Cq * v - Dk * x
            hu = Dk / k
            dV1 = Cq * dV
            dV1 -= Dk * dQ
            dV1 += (Cqk * v - Dkk * x - hu * qe) * dK
            dV1[ls] += hu * dU
            dV1[ps] += (Cqa * v - Dka * x) * da
            return q1, v1, dQ1, dV1

        for _ in range(self.substeps):
            k1, dK1 = stiff(q, dQ)
            qp, _, dQp, _ = stage(q, v, k1, dQ, dV, dK1, False)
            kp, dKp = stiff(qp, dQp)
            k2, dK2 = 0.5 * (k1 + kp), 0.5 * (dK1 + dKp)
            q, v, dQ, dV = stage(q, v, k2, dQ, dV, dK2, True)
        return q, v, dQ, dV
