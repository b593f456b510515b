"""The Berger-type nonlinear membrane in modal coordinates (uniform tension following the mean stretch).

Physics (spec §8, uniform in-plane strain): with ``z = Phi q`` the mean stretches are
``sx = z^T Gx z / (2A)``, ``sy = z^T Gy z / (2A)`` and the tensions follow them::

    Tx = C ((e0x + sx) + nu (e0y + sy)),   Ty = C ((e0y + sy) + nu (e0x + sx)),   C = E h / (1 - nu^2)
    rho h M z'' + d (gamma M + eta K0) z' + (Tx Gx + Ty Gy) z = M f

``K0 = Tx0 Gx + Ty0 Gy`` is the tension matrix of the prestress alone (the damping stays linear,
the convention of the full-order truth models, :mod:`wingopt.membrane.full`) and ``d`` a damping
factor. In the modes of :class:`~wingopt.membrane.modal.base.ModalMembrane` every mode is a damped
oscillator; they couple only through the two scalar tensions ``Tx(t), Ty(t)``: the model's force
law (:data:`~.laws.BERGER`), integrated by the modal membranes' one compiled loop (:mod:`.kernels`:
exact oscillators for a frozen tension, predictor-corrector on the tension).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError
from wingopt.membrane.modal.base import ModalMembrane
from wingopt.membrane.modal.laws import BERGER
from wingopt.membrane.model import MembraneModel

__all__ = ["BergerModal"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class BergerModal(ModalMembrane):
    """Modal Berger membrane; ``stretch_gain`` multiplies the deflection's own stretch (1: Berger)."""

    stretch_gain: float = 1.0
    physics = "berger"

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

    def force_law(self, nonlinear: bool = True, dtype=float) -> tuple:
        """Uniform tension (:data:`~.laws.BERGER`): every mode's stiffness follows the two mean stretches."""
        nu, C = self.model.problem.material.poisson_ratio, self.stiffness_c
        on = self.stretch_gain if nonlinear else 0.0
        ia = 1.0 / (2.0 * self.area)
        # k_j = Tx kx_j + Ty ky_j with Tx, Ty linear in the strains: k = k0 + Sx * kxs + Sy * kys
        K = np.array([self.kx, self.ky, on * C * ia * (self.kx + nu * self.ky), on * C * ia * (self.ky + nu * self.kx)])
        r = self.m if nonlinear else 0
        return BERGER, r, np.zeros((0, 0), dtype), np.zeros((0, 0, 0)), K.astype(dtype, copy=False)

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
