"""Material laws: bending rigidity of laminates (eqs. 4.4–4.11) and of piezocomposite patch pairs (eqs. 4.23–4.25).

A ply of an orthotropic material has, in its material axes (1 = along the fibres), the plane-stress
reduced stiffness (eq. 4.5)::

    Q = [[E1/(1-v12 v21), v21 E1/(1-v12 v21), 0],
         [v12 E2/(1-v12 v21), E2/(1-v12 v21), 0],
         [0, 0, G12]]                      (v21 = v12 E2/E1, reciprocity)

acting on the strains ``[eps_x, eps_y, gamma_xy]`` (engineering shear). Rotated so that its fibres
make the angle ``alpha`` with the x-axis, it becomes ``Qbar = T_sigma^-1 Q T_eps`` (eq. 4.7), and a
stack of plies between ``t_0 < t_1 < ... < t_N`` (measured from the mid-plane) has the bending rigidity
(eq. 4.11)::

    D = Σ_k (1/3) Qbar_k (t_k^3 - t_{k-1}^3)

so that the moments are ``[Mx, My, Mxy] = D [w_xx, w_yy, 2 w_xy]`` (up to the sign convention of the
curvature, which cancels in the energy ``½ ∫ κ^T D κ``). The Kelvin–Voigt matrices have the same
structure with the viscosities in place of the moduli (eq. 4.6).

The dissertation rotates stresses with the strain matrix ``T_eps`` too (``T^-1 D* T``); that is exact
for plies at 0° and 90° (the only angles the seed uses) but not invariant for an isotropic ply at other
angles, so here the stress rotation ``T_sigma`` is used (the textbook form; identical for 0°/90°).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from wingopt.errors import InputError

__all__ = [
    "reduced_stiffness",
    "isotropic_stiffness",
    "rotate",
    "laminate_rigidity",
    "symmetric_pair_rigidity",
    "plate_rigidity",
    "moment_integrals",
]


def reduced_stiffness(e1: float, e2: float, g12: float, nu12: float) -> np.ndarray:
    """Plane-stress reduced stiffness ``Q`` (3x3) of an orthotropic ply in its material axes (eq. 4.5).

    ``nu12`` is the major Poisson ratio (strain in 2 from stress in 1); the minor one follows from
    reciprocity, ``nu21 = nu12 e2 / e1``.
    """
    if not (e1 > 0 and e2 > 0 and g12 > 0):
        raise InputError(f"moduli e1={e1!r}, e2={e2!r}, g12={g12!r}: expected positive numbers (Pa)")
    nu21 = nu12 * e2 / e1
    det = 1.0 - nu12 * nu21
    if det <= 0:
        raise InputError(f"nu12 = {nu12!r}: 1 - nu12 nu21 = {det:.3g} <= 0, the ply would not be stable")
    return np.array(
        [
            [e1 / det, nu21 * e1 / det, 0.0],
            [nu12 * e2 / det, e2 / det, 0.0],
            [0.0, 0.0, g12],
        ]
    )


def isotropic_stiffness(e: float, nu: float) -> np.ndarray:
    """``Q`` of an isotropic material: ``E/(1-nu^2) [[1, nu, 0], [nu, 1, 0], [0, 0, (1-nu)/2]]``."""
    return reduced_stiffness(e, e, e / (2.0 * (1.0 + nu)), nu)


def rotate(q: np.ndarray, angle_deg: float) -> np.ndarray:
    """``Qbar = T_sigma^-1 Q T_eps`` for fibres at ``angle_deg`` from the x-axis (counter-clockwise)."""
    a = np.deg2rad(angle_deg)
    c, s = np.cos(a), np.sin(a)
    t_eps = np.array([[c * c, s * s, c * s], [s * s, c * c, -c * s], [-2 * c * s, 2 * c * s, c * c - s * s]])
    t_sig = np.array([[c * c, s * s, 2 * c * s], [s * s, c * c, -2 * c * s], [-c * s, c * s, c * c - s * s]])
    out = np.linalg.solve(t_sig, np.asarray(q) @ t_eps)
    # Exact zeros stay zeros at 0°/90° (cos(pi/2) is 6e-17, not 0).
    out[np.abs(out) < 1e-14 * np.abs(q).max()] = 0.0
    return 0.5 * (out + out.T)


def laminate_rigidity(plies: Sequence[tuple[np.ndarray, float]], interfaces: Sequence[float]) -> np.ndarray:
    """``D = Σ_k (1/3) Qbar_k (t_k^3 - t_{k-1}^3)`` (eq. 4.11).

    Parameters
    ----------
    plies : sequence of ``(Q, angle_deg)``
        Each ply's material-axes stiffness (or Kelvin–Voigt viscosity) matrix and fibre angle, from
        the bottom of the stack to the top.
    interfaces : sequence of float
        The ``len(plies) + 1`` ply boundaries ``t_0 < t_1 < ...`` in m, measured from the mid-plane.
    """
    t = np.asarray(interfaces, dtype=float)
    if t.size != len(plies) + 1 or np.any(np.diff(t) <= 0):
        raise InputError(f"interfaces {list(t)}: expected {len(plies) + 1} increasing ply boundaries")
    D = np.zeros((3, 3))
    for (q, angle), lo, hi in zip(plies, t[:-1], t[1:]):
        D += rotate(q, angle) * (hi**3 - lo**3) / 3.0
    return D


def plate_rigidity(q: np.ndarray, thickness: float, angles: Sequence[float] = (0.0,)) -> np.ndarray:
    """Rigidity of a laminate of equal plies of one material, total ``thickness``, centred on z = 0."""
    n = len(angles)
    if n < 1 or not thickness > 0:
        raise InputError(f"laminate: {n} plies of total thickness {thickness!r}: expected >= 1 ply, thickness > 0")
    interfaces = np.linspace(-thickness / 2.0, thickness / 2.0, n + 1)
    return laminate_rigidity([(q, a) for a in angles], interfaces)


def moment_integrals(substrate: float | np.ndarray, layer: float) -> tuple[np.ndarray, np.ndarray]:
    """``c2 = ∫ z dz`` and ``c3 = ∫ z^2 dz`` over ``[h/2, h/2 + h_pz]`` (eqs. 4.23–4.26)."""
    lo = 0.5 * np.asarray(substrate, dtype=float)
    hi = lo + layer
    return (hi**2 - lo**2) / 2.0, (hi**3 - lo**3) / 3.0


def symmetric_pair_rigidity(q: np.ndarray, substrate: float | np.ndarray, layer: float) -> np.ndarray:
    """Rigidity added by a patch pair of thickness ``layer`` bonded on both faces (eqs. 4.23–4.25).

    ``2 c3 Q`` with ``c3 = ∫_{h/2}^{h/2+h_pz} z^2 dz``: the top and bottom patches contribute equally.
    A ``substrate`` array gives an array of matrices, shape ``substrate.shape + (3, 3)``.
    """
    _, c3 = moment_integrals(substrate, layer)
    return 2.0 * np.asarray(c3)[..., None, None] * np.asarray(q)
