"""Berger-type nonlinear membrane in modal coordinates: the fast model of the realistic estimator.

Physics (spec §8, uniform in-plane strain): with ``z = Phi q`` and ``Gx = ∫ phi_x phi_x^T``,
``Gy = ∫ phi_y phi_y^T``, the mean stretches are ``sx = z^T Gx z / (2A)``, ``sy = z^T Gy z / (2A)``
and the tensions follow them::

    Tx = C ((e0x + sx) + nu (e0y + sy)),   Ty = C ((e0y + sy) + nu (e0x + sx)),   C = E h / (1 - nu^2)
    rho h M z'' + d (gamma M + eta K0) z' + (Tx Gx + Ty Gy) z = M f

``K0 = Tx0 Gx + Ty0 Gy`` is the tension matrix of the prestress alone (the damping stays linear,
the convention of the team's truth simulators, ``wingopt.membrane.nonlinear``) and ``d`` a damping
factor. The small-deflection limit is the linear model of spec §2 exactly.

Structure used: on a tensor-product spline space ``M^-1 Gx`` and ``M^-1 Gy`` commute, so the modes
of ``(Gx + c Gy, M)`` for a generic ``c`` are tensor products that diagonalise ``Gx`` and ``Gy``
*simultaneously* (``kx_j``, ``ky_j``). Given the two scalar tensions every mode is an independent
damped oscillator; the modes couple only through ``Tx(t), Ty(t)``. One sample is integrated with the
exact solution of each oscillator for a frozen tension, predictor (tension at the step start) and
corrector (mean of the start and predicted-end tensions): second order in the tension variation,
exact for the linear model. The oscillator solution is written with the entire functions
``cos(sqrt(z))`` and ``sin(sqrt(z))/sqrt(z)`` of ``z = (k - c^2/4) h^2``, so it is analytic in every
argument (under- and over-damped alike) and complex-step differentiation gives exact Jacobians.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from wingopt.errors import InputError
from wingopt.estimation.realistic.tangent import simulate_tangent
from wingopt.fe import DX, DY, VALUE, assemble, separable
from wingopt.membrane import MembraneModel

__all__ = ["BergerModal", "oscillator_step"]

log = logging.getLogger(__name__)

_SPLIT = 1.0 + np.sqrt(2.0) / 10.0
"""Weight of ``Gy`` in the pencil whose modes diagonalise ``Gx`` and ``Gy`` (breaks the degeneracies
of the rectangle, e.g. (2,2) and (4,1) at W = 2L, without changing the eigenvectors)."""


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


@dataclass(frozen=True, eq=False)
class BergerModal:
    """Modal Berger membrane (lowest ``m`` tensor-product modes of the nominal prestress).

    Attributes
    ----------
    model : MembraneModel
    shapes : ndarray ``(n, m)``, ``rho h M``-orthonormal
    kx, ky : ndarray ``(m,)``
        ``phi_j^T Gx phi_j`` and ``phi_j^T Gy phi_j`` (modal stiffness per unit tension).
    sensor_matrices : ndarray ``(p, m, m)``
    input_matrix : ndarray ``(m, n)``
        ``Phi^T M``: modal force of load coefficients ``f`` (``p = M f``).
    dt : float
        Sample period; ``substeps`` integration steps per sample.
    """

    model: MembraneModel
    shapes: np.ndarray
    kx: np.ndarray
    ky: np.ndarray
    sensor_matrices: np.ndarray
    input_matrix: np.ndarray
    dt: float
    substeps: int = 1
    dynamic: int = 0
    scheme: str = "midpoint"
    stretch_gain: float = 1.0

    @classmethod
    def build(
        cls,
        model: MembraneModel,
        modes: int = 20,
        dt: float | None = None,
        substeps: int = 1,
        dynamic: int | None = None,
        scheme: str = "midpoint",
        stretch_gain: float = 1.0,
    ) -> BergerModal:
        """Modes of ``model``'s space (``modes`` lowest at the nominal isotropic prestress), the lowest
        ``dynamic`` of them (default all) integrated, the others quasi-static. ``scheme``: the
        tension over a step, ``"midpoint"`` (predictor-corrector, two oscillator steps) or
        ``"extrapolated"`` (``1.5 T_k - 0.5 T_{k-1}``, one oscillator step; both second order).
        ``stretch_gain`` multiplies the deflection's own stretch (1: Berger; about 1.45 matches the
        Föppl–von Kármán membrane's mean stiffening at 200 Pa, docs/membrane_nonlinear.md §4)."""
        n = model.n
        if not 1 <= modes <= n:
            raise InputError(f"modes = {modes}: expected 1..{n} for this mesh")
        if substeps < 1:
            raise InputError(f"substeps = {substeps}: expected >= 1")
        space = model.space
        gx = assemble(space, separable((1.0, DX, DX))).toarray()
        gy = assemble(space, separable((1.0, DY, DY))).toarray()
        mass = model.problem.material.areal_density * assemble(space, separable((1.0, VALUE, VALUE))).toarray()
        _, vecs = sla.eigh(gx + _SPLIT * gy, mass)
        kx = np.einsum("ij,ik,kj->j", vecs, gx, vecs)
        ky = np.einsum("ij,ik,kj->j", vecs, gy, vecs)
        order = np.argsort(kx + ky)[:modes]
        Phi, kx, ky = vecs[:, order], kx[order], ky[order]
        off = np.abs(Phi.T @ gx @ Phi - np.diag(kx)).max() / kx.max()
        if off > 1e-6:  # pragma: no cover - holds for every tensor-product spline space
            raise InputError(f"modal Berger model: Gx is not diagonal in the modes ({off:.1e})")
        Chat = np.stack([Phi.T @ (C @ Phi) for C in model.sensors.matrices])
        B = np.asarray((model.gram @ Phi).T)
        dt = model.problem.identification.dt if dt is None else float(dt)
        dynamic = modes if dynamic is None else int(dynamic)
        if not 1 <= dynamic <= modes:
            raise InputError(f"dynamic modes = {dynamic}: expected 1..{modes}")
        if scheme not in ("midpoint", "extrapolated"):
            raise InputError(f"scheme = {scheme!r}: expected 'midpoint' or 'extrapolated'")
        if not (np.isfinite(stretch_gain) and stretch_gain >= 0):
            raise InputError(f"stretch_gain = {stretch_gain!r}: expected a non-negative number")
        return cls(model, Phi, kx, ky, Chat, B, dt, int(substeps), dynamic, scheme, float(stretch_gain))

    # -- sizes and constants ---------------------------------------------------------------
    @property
    def m(self) -> int:
        return self.kx.size

    @property
    def p(self) -> int:
        return self.sensor_matrices.shape[0]

    @property
    def area(self) -> float:
        return self.model.problem.width * self.model.problem.height

    @property
    def stiffness_c(self) -> float:
        """``C = E h / (1 - nu^2)`` (N/m)."""
        mat = self.model.problem.material
        return mat.youngs_modulus * mat.thickness / (1.0 - mat.poisson_ratio**2)

    @property
    def prestrain(self) -> float:
        return self.model.problem.material.prestrain

    def omega(self, ex: float | None = None, ey: float | None = None) -> np.ndarray:
        """Linear (small-deflection) circular frequencies at prestrains ``ex, ey`` (default: the file's)."""
        tx, ty = self.tensions(self.prestrain if ex is None else ex, self.prestrain if ey is None else ey)
        return np.sqrt(tx * self.kx + ty * self.ky)

    def tensions(self, ex, ey):
        """``(Tx, Ty)`` of total strains ``ex, ey``."""
        nu = self.model.problem.material.poisson_ratio
        C = self.stiffness_c
        return C * (ex + nu * ey), C * (ey + nu * ex)

    def stretch(self, q):
        """Mean stretches ``(sx, sy)`` of modal displacements ``q`` (last axis the modes)."""
        two_a = 2.0 * self.area
        return (q * q) @ self.kx / two_a, (q * q) @ self.ky / two_a

    # -- dynamics --------------------------------------------------------------------------
    def _coefficients(self, ex, ey, damping):
        """Modal damping ``c_j`` (..., m) for parameters of shape (...)."""
        mat = self.model.problem.material
        tx0, ty0 = self.tensions(np.asarray(ex)[..., None], np.asarray(ey)[..., None])
        kv = mat.kelvin_voigt * (tx0 * self.kx + ty0 * self.ky)
        return np.asarray(damping)[..., None] * (mat.viscous / mat.areal_density + kv)

    def simulate_linear(self, q0, v0, forces, ex, ey, damping=1.0):
        """As :meth:`simulate` with the deflection's own stretch left out (the linear model)."""
        return self.simulate(q0, v0, forces, ex, ey, damping, nonlinear=False)

    def simulate(self, q0, v0, forces, ex, ey, damping=1.0, nonlinear: bool = True):
        """Modal displacements at every sample.

        The first ``dynamic`` modes are integrated; the others follow the load quasi-statically
        at the current tension (their stretch enters the tension one sample late), the
        mode-acceleration idea: fast modes respond statically within a few ms.

        Parameters
        ----------
        q0, v0 : array ``(..., dynamic)``
            Initial displacement and velocity of the dynamic modes (leading batch axes allowed;
            complex allowed).
        forces : array ``(N, ..., m)``
            Modal force held over each sample interval.
        ex, ey, damping : array ``(...)`` or float
            Prestrains and damping factor.

        Returns
        -------
        Q : array ``(N + 1, ..., m)``
        """
        forces = np.asarray(forces)
        N = forces.shape[0]
        md = self.dynamic
        dtype = np.result_type(q0, v0, forces, ex, ey, damping, float)
        q = np.array(q0, dtype=dtype)
        v = np.array(v0, dtype=dtype)
        ex = np.asarray(ex, dtype=dtype)
        ey = np.asarray(ey, dtype=dtype)
        c = self._coefficients(ex, ey, np.asarray(damping, dtype=dtype))[..., :md]
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
        kx, ky, kxd, kyd = self.kx[md:], self.ky[md:], self.kx[:md], self.ky[:md]
        k0d, k0s, kxsd, kxss, kysd, kyss = k0[..., :md], k0[..., md:], kxs[:md], kxs[md:], kys[:md], kys[md:]
        e = np.exp(-0.5 * c * h)

        def stiffness(qd, sx, sy):
            qq = qd * qd
            return (qq @ kxd + sx)[..., None], (qq @ kyd + sy)[..., None]

        sx0 = sy0 = 0.0
        Sx, Sy = stiffness(q, sx0, sy0)
        qs = forces[0][..., md:] / (k0s + Sx * kxss + Sy * kyss)
        Q[0, ..., :md], Q[0, ..., md:] = q, qs
        extrapolate = self.scheme == "extrapolated"
        k_old = None
        for k in range(N):
            u = forces[k]
            ud, us = u[..., :md], u[..., md:]
            qq = qs * qs
            sx, sy = qq @ kx, qq @ ky
            for _ in range(self.substeps):
                Sx, Sy = stiffness(q, sx, sy)
                kk = k0d + Sx * kxsd + Sy * kysd
                if extrapolate:
                    k_new = kk
                    kk = kk if k_old is None else 1.5 * kk - 0.5 * k_old
                    k_old = k_new
                    q, v = oscillator_step(q, v, ud, kk, c, h, e)
                    continue
                qp, _ = oscillator_step(q, v, ud, kk, c, h, e)
                Sx, Sy = stiffness(qp, sx, sy)
                kk = 0.5 * (kk + k0d + Sx * kxsd + Sy * kysd)
                q, v = oscillator_step(q, v, ud, kk, c, h, e)
            Sx, Sy = stiffness(q, sx, sy)
            qs = us / (k0s + Sx * kxss + Sy * kyss)
            Q[k + 1, ..., :md], Q[k + 1, ..., md:] = q, qs
        return Q

    def simulate_tangent(self, q0, v0, forces, ex, ey, damping, dq0, dv0, dpar, dforces, nonlinear: bool = True):
        """Trajectory and exact tangents (:func:`~wingopt.estimation.realistic.tangent.simulate_tangent`)."""
        return simulate_tangent(self, q0, v0, forces, ex, ey, damping, dq0, dv0, dpar, dforces, nonlinear)

    def outputs(self, Q: np.ndarray) -> np.ndarray:
        """Sensor outputs ``(N, p)`` of real modal displacements ``Q`` ``(N, m)``."""
        return np.einsum("kpi,ki->kp", self.sensor_products(Q), Q)

    def sensor_products(self, Q: np.ndarray) -> np.ndarray:
        """``C_p q_k`` ``(N, p, m)`` for modal displacements ``Q`` ``(N, m)`` (one GEMM)."""
        p, m = self.p, self.m
        return (Q @ self.sensor_matrices.reshape(p * m, m).T).reshape(Q.shape[0], p, m)

    def deflection(self, q: np.ndarray) -> np.ndarray:
        """Deflection coefficients ``Phi q``."""
        return np.asarray(q) @ self.shapes.T

    def to_modal(self, z: np.ndarray) -> np.ndarray:
        """Modal coordinates of deflection coefficients (mass-orthonormal projection)."""
        return self.shapes.T @ (self.model.mass @ z)
