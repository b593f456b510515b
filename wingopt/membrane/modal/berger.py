"""The Berger-type nonlinear membrane in modal coordinates (uniform tension following the mean stretch).

Physics (spec §8, uniform in-plane strain): with ``z = Phi q`` the mean stretches are
``sx = z^T Gx z / (2A)``, ``sy = z^T Gy z / (2A)`` and the tensions follow them::

    Tx = C ((e0x + sx) + nu (e0y + sy)),   Ty = C ((e0y + sy) + nu (e0x + sx)),   C = E h / (1 - nu^2)
    rho h M z'' + d (gamma M + eta K0) z' + (Tx Gx + Ty Gy) z = M f

``K0 = Tx0 Gx + Ty0 Gy`` is the tension matrix of the prestress alone (the damping stays linear,
the convention of the full-order truth models, :mod:`wingopt.membrane.full`) and ``d`` a damping
factor. In the modes of :class:`~wingopt.membrane.modal.base.ModalMembrane` every mode is a damped
oscillator; they couple only through the two scalar tensions ``Tx(t), Ty(t)``. One sample is
integrated with the exact solution of each oscillator (:func:`~.oscillator.oscillator_step`) for a
frozen tension, predictor (tension at the step start) and corrector (mean of the start and
predicted-end tensions): second order in the tension variation, exact for the linear model.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError
from wingopt.membrane.modal.base import ModalMembrane
from wingopt.membrane.modal.oscillator import oscillator_step
from wingopt.membrane.modal.tangent import simulate_tangent
from wingopt.membrane.model import MembraneModel

__all__ = ["BergerModal"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class BergerModal(ModalMembrane):
    """Modal Berger membrane; ``stretch_gain`` multiplies the deflection's own stretch (1: Berger)."""

    stretch_gain: float = 1.0

    @classmethod
    def build(
        cls,
        model: MembraneModel,
        modes: int = 20,
        dt: float | None = None,
        substeps: int = 1,
        stretch_gain: float = 1.0,
    ) -> BergerModal:
        """The ``modes`` lowest modes of ``model`` at ``dt`` (``substeps`` steps per sample).
        ``stretch_gain`` about 1.45 matches the Föppl–von Kármán membrane's mean stiffening at
        200 Pa (docs/membrane_nonlinear.md §4)."""
        if not (np.isfinite(stretch_gain) and stretch_gain >= 0):
            raise InputError(f"stretch_gain = {stretch_gain!r}: expected a non-negative number")
        return cls(**cls.modal_fields(model, modes, dt, substeps), stretch_gain=float(stretch_gain))

    def simulate(self, q0, v0, forces, ex, ey, damping=1.0, nonlinear: bool = True):
        """Modal displacements at every sample.

        Parameters
        ----------
        q0, v0 : array ``(..., m)``
            Initial displacement and velocity (leading batch axes allowed; complex allowed).
        forces : array ``(N, ..., m)``
            Modal force held over each sample interval.
        ex, ey, damping : array ``(...)`` or float
            Prestrains and damping factor.
        nonlinear : bool
            ``False`` leaves the deflection's own stretch out (the linear membrane).

        Returns
        -------
        Q : array ``(N + 1, ..., m)``
        """
        forces = np.asarray(forces)
        N = forces.shape[0]
        dtype = np.result_type(q0, v0, forces, ex, ey, damping, float)
        q = np.array(q0, dtype=dtype)
        v = np.array(v0, dtype=dtype)
        ex = np.asarray(ex, dtype=dtype)
        ey = np.asarray(ey, dtype=dtype)
        c = self._coefficients(ex, ey, np.asarray(damping, dtype=dtype))
        exb, eyb = ex[..., None], ey[..., None]
        h = self.dt / self.substeps
        Q = np.empty((N + 1,) + np.broadcast_shapes(q.shape[:-1], forces.shape[1:-1]) + (self.m,), dtype=dtype)
        nu = self.model.problem.material.poisson_ratio
        C = self.stiffness_c
        ia = 1.0 / (2.0 * self.area)
        on = self.stretch_gain if nonlinear else 0.0
        # k_j = Tx kx_j + Ty ky_j with Tx, Ty linear in the strains: k = k0 + Sx * kxs + Sy * kys
        k0 = C * ((exb + nu * eyb) * self.kx + (eyb + nu * exb) * self.ky)
        kxs = on * C * ia * (self.kx + nu * self.ky)
        kys = on * C * ia * (self.ky + nu * self.kx)
        e = np.exp(-0.5 * c * h)

        def stiffness(q):
            qq = q * q
            return k0 + (qq @ self.kx)[..., None] * kxs + (qq @ self.ky)[..., None] * kys

        Q[0] = q
        for k in range(N):
            u = forces[k]
            for _ in range(self.substeps):
                kk = stiffness(q)
                qp, _ = oscillator_step(q, v, u, kk, c, h, e)
                kk = 0.5 * (kk + stiffness(qp))
                q, v = oscillator_step(q, v, u, kk, c, h, e)
            Q[k + 1] = q
        return Q

    def internal_force(self, q, ex, ey, nonlinear: bool = True):
        """``k(q) q`` with ``k = k0 + Sx kxs + Sy kys`` and its Jacobian ``(m, m)``."""
        nu, C = self.model.problem.material.poisson_ratio, self.stiffness_c
        on = self.stretch_gain if nonlinear else 0.0
        ia = 1.0 / (2.0 * self.area)
        k0 = self.omega(ex, ey) ** 2
        kxs, kys = on * C * ia * (self.kx + nu * self.ky), on * C * ia * (self.ky + nu * self.kx)
        sx, sy = (q * q) @ self.kx, (q * q) @ self.ky
        k = k0 + sx * kxs + sy * kys
        J = np.diag(k) + np.outer(q * kxs, 2 * self.kx * q) + np.outer(q * kys, 2 * self.ky * q)
        return k * q, J

    def simulate_tangent(self, q0, v0, forces, ex, ey, damping, dq0, dv0, dpar, dforces, nonlinear: bool = True):
        """Trajectory and exact tangents (:func:`~wingopt.membrane.modal.tangent.simulate_tangent`)."""
        return simulate_tangent(self, q0, v0, forces, ex, ey, damping, dq0, dv0, dpar, dforces, nonlinear)
