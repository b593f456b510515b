"""The identifiable parameters of a membrane: prestrains and damping factors, one value type.

:class:`MembraneParameters` is what a forward model (:mod:`wingopt.membrane.forward`) is run
with and what an estimator identifies: the prestrains ``eps0_x, eps0_y`` (a membrane glued on a
frame is prestrained by an uncertain amount, often unequal in x and y; spec §8) and factors on the
problem file's two damping terms. Damping of every nonlinear model: ``D = s_v gamma M + s_kv eta
K_T0`` with ``K_T0 = Tx0 Gx + Ty0 Gy`` the tension matrix of the *prestress*: it stays linear, so
the small-load limit is the linear model exactly.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError

__all__ = ["MembraneParameters", "membrane_stiffness", "prestress_tensions"]


@dataclass(frozen=True)
class MembraneParameters:
    """Identifiable membrane parameters.

    Attributes
    ----------
    eps0_x, eps0_y : float
        Prestrain in x (chordwise) and y (spanwise); may be zero (no prestress).
    viscous_scale, kelvin_voigt_scale : float
        Factors on the problem's ``gamma`` and ``eta``.
    """

    eps0_x: float
    eps0_y: float
    viscous_scale: float = 1.0
    kelvin_voigt_scale: float = 1.0

    NAMES = ("eps0_x", "eps0_y", "viscous_scale", "kelvin_voigt_scale")

    def __post_init__(self) -> None:
        for name in self.NAMES:
            val = getattr(self, name)
            if not (np.isfinite(val) and val >= 0):
                raise InputError(f"{name} = {val!r}: expected a finite non-negative number")

    @classmethod
    def nominal(cls, problem, prestrain: tuple[float, float] | None = None, damping_scale=1.0) -> MembraneParameters:
        """The problem file's isotropic prestrain (or ``prestrain = (ex, ey)``) and damping.

        ``damping_scale`` is one factor for both damping terms or a pair ``(viscous, kelvin_voigt)``.
        """
        e = problem.material.prestrain
        ex, ey = (e, e) if prestrain is None else (float(prestrain[0]), float(prestrain[1]))
        sv, sk = (damping_scale, damping_scale) if np.isscalar(damping_scale) else damping_scale
        return cls(ex, ey, float(sv), float(sk))

    def replace(self, **kw) -> MembraneParameters:
        return dataclasses.replace(self, **kw)

    def as_array(self) -> np.ndarray:
        return np.array([getattr(self, n) for n in self.NAMES])


def membrane_stiffness(material) -> float:
    """``C = E h / (1 - nu^2)`` (N/m)."""
    return material.youngs_modulus * material.thickness / (1.0 - material.poisson_ratio**2)


def prestress_tensions(material, params: MembraneParameters) -> tuple[float, float]:
    """``Tx0 = C (eps0_x + nu eps0_y)``, ``Ty0 = C (eps0_y + nu eps0_x)`` (N/m)."""
    C, nu = membrane_stiffness(material), material.poisson_ratio
    return C * (params.eps0_x + nu * params.eps0_y), C * (params.eps0_y + nu * params.eps0_x)
