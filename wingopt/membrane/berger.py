"""Reduced nonlinear membrane for estimation: uniform (Berger-type) tension (spec §8).

The in-plane strain is taken uniform and equal to its mean, so the tensions follow the mean
stretch of the deflection::

    s_x = (1/2A) ∫ w_x^2 = z^T Gx z / (2A),   s_y = z^T Gy z / (2A)
    Tx = C ((eps0_x + s_x) + nu (eps0_y + s_y)),   Ty = C ((eps0_y + s_y) + nu (eps0_x + s_x))
    F(z) = Tx(z) Gx z + Ty(z) Gy z

with ``Gx = ∫ phi_x phi_x^T``, ``Gy = ∫ phi_y phi_y^T`` (the linear model's ``K_T`` is
``T (Gx + Gy)``). ``F`` is the gradient of ``U = (C A/2) (e_x^2 + e_y^2 + 2 nu e_x e_y)`` with
``e = eps0 + s``, so the tangent is symmetric: ``Tx Gx + Ty Gy`` plus the rank-2 term
``(C/A) [gx (gx + nu gy)^T + gy (gy + nu gx)^T]``, ``gx = Gx z``, ``gy = Gy z``.

**Separable modes.** ``M = Mx⊗My``, ``Gx = Kx⊗My``, ``Gy = Mx⊗Ky`` with the 1-D Gram matrices;
the 1-D eigenvectors ``Kx Vx = Mx Vx diag(lx)`` give ``V = Vx⊗Vy`` with ``V^T M V = I``,
``V^T Gx V = diag(lx⊗1)``, ``V^T Gy V = diag(1⊗ly)`` — for *every* pair of tensions. In
``z = V q`` the Berger model is ``n`` damped oscillators coupled only through the two scalars
``Tx, Ty``, and the mode shapes do not depend on the parameters. Time stepping and parameter
sensitivities (:mod:`wingopt.membrane.berger_sim`) therefore cost O(n) per step.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from wingopt.errors import InputError, SolverError
from wingopt.membrane.model import MembraneModel
from wingopt.membrane.nonlinear import MembraneParameters, PrestressedOperators, membrane_stiffness

__all__ = ["BergerMembrane", "SeparableModes"]


@dataclass(frozen=True, eq=False)
class SeparableModes:
    """``V = Vx⊗Vy`` (M-orthonormal) and the 1-D eigenvalues ``lx, ly`` of ``Gx, Gy`` against ``M``."""

    vx: np.ndarray
    vy: np.ndarray
    lam_x: np.ndarray  # (n,) eigenvalue of Gx for each 2-D mode (lx_i repeated over j)
    lam_y: np.ndarray
    mx: np.ndarray  # 1-D Gram matrices (dense), for q = V^T M z
    my: np.ndarray

    @classmethod
    def build(cls, space) -> SeparableModes:
        mx, kx = space.bx.gram(0, 0).toarray(), space.bx.gram(1, 1).toarray()
        my, ky = space.by.gram(0, 0).toarray(), space.by.gram(1, 1).toarray()
        lx, vx = sla.eigh(kx, mx)
        ly, vy = sla.eigh(ky, my)
        return cls(vx, vy, np.repeat(lx, ly.size), np.tile(ly, lx.size), mx, my)

    @property
    def shape(self) -> tuple[int, int]:
        return self.vx.shape[0], self.vy.shape[0]

    def _apply(self, left: np.ndarray, right: np.ndarray, a: np.ndarray) -> np.ndarray:
        """``(left ⊗ right) a`` for ``a`` of shape ``(n,)`` or ``(n, k)`` (sum factorisation)."""
        nx, ny = left.shape[1], right.shape[1]
        if a.ndim == 1:
            return (left @ a.reshape(nx, ny) @ right.T).ravel()
        k = a.shape[1]
        X = (left @ a.reshape(nx, ny * k)).reshape(left.shape[0], ny, k)
        return np.einsum("jb,abk->ajk", right, X).reshape(left.shape[0] * right.shape[0], k)

    def to_field(self, q: np.ndarray) -> np.ndarray:
        """``z = V q`` for ``q`` of shape ``(n,)`` or ``(n, k)``."""
        return self._apply(self.vx, self.vy, q)

    def to_modal(self, z: np.ndarray) -> np.ndarray:
        """``q = V^T M z`` (the M-orthogonal projection) for ``(n,)`` or ``(n, k)``."""
        return self._apply(self.vx.T @ self.mx, self.vy.T @ self.my, z)

    def to_modal_force(self, p: np.ndarray) -> np.ndarray:
        """``V^T p`` for a force vector ``p`` (``(n,)`` or ``(n, k)``)."""
        return self._apply(self.vx.T, self.vy.T, p)


class BergerMembrane(PrestressedOperators):
    """Uniform-tension nonlinear membrane on the linear model's mesh.

    Parameters
    ----------
    model : MembraneModel
        The linear model (space, Gram and sensor matrices are shared).
    params : MembraneParameters, optional
        Default: the problem file's prestrain and damping.
    stretch_gain : float
        Factor ``kappa`` on the stretch-induced tension, ``T = T0 + kappa C (s + nu s')``:
        1 is Berger's model; a value calibrated on the FvK model (about 1.45 for L1–L3 shapes,
        1.75 for the leading-edge load, measured in docs/membrane_nonlinear.md) makes the
        uniform tension stiffen like the non-uniform FvK tension does on average.
    """

    def __init__(
        self, model: MembraneModel, params: MembraneParameters | None = None, stretch_gain: float = 1.0
    ) -> None:
        if not (np.isfinite(stretch_gain) and stretch_gain >= 0):
            raise InputError(f"stretch_gain = {stretch_gain!r}: expected a finite non-negative factor")
        self.stretch_gain = float(stretch_gain)
        self.linear = model
        self.problem = model.problem
        self.params = MembraneParameters.nominal(model.problem) if params is None else params
        self.space = model.space
        self.n = model.n
        mat = self.problem.material
        self.C, self.nu = membrane_stiffness(mat), mat.poisson_ratio
        self.area = self.problem.width * self.problem.height
        self.rho_h = mat.areal_density

    @classmethod
    def from_problem(
        cls, problem, nodes=None, params: MembraneParameters | None = None, stretch_gain: float = 1.0
    ) -> BergerMembrane:
        return cls(MembraneModel.from_problem(problem, nodes), params, stretch_gain)

    def with_params(self, params: MembraneParameters, stretch_gain: float | None = None) -> BergerMembrane:
        """The same operators with other parameters (no re-assembly)."""
        other = BergerMembrane.__new__(BergerMembrane)
        other.__dict__.update(self.__dict__)
        other.params = params
        if stretch_gain is not None:
            other.stretch_gain = float(stretch_gain)
        for key in ("damping", "linear_stiffness"):
            other.__dict__.pop(key, None)
        return other

    # -- operators ------------------------------------------------------------------------------

    @cached_property
    def modes(self) -> SeparableModes:
        return SeparableModes.build(self.space)

    # -- force and derivatives ------------------------------------------------------------------
    def stretch(self, z: np.ndarray) -> tuple[float, float]:
        """Mean stretches ``s_x, s_y`` of the deflection ``z``."""
        return float(z @ (self.gx @ z)) / (2 * self.area), float(z @ (self.gy @ z)) / (2 * self.area)

    def tensions(self, z: np.ndarray) -> tuple[float, float]:
        """``Tx(z), Ty(z)`` (N/m)."""
        sx, sy = self.stretch(z)
        p, C, nu, g = self.params, self.C, self.nu, self.stretch_gain
        ex, ey = p.eps0_x + g * sx, p.eps0_y + g * sy
        return C * (ex + nu * ey), C * (ey + nu * ex)

    def force(self, z: np.ndarray) -> np.ndarray:
        """``F(z) = Tx(z) Gx z + Ty(z) Gy z``."""
        tx, ty = self.tensions(z)
        return tx * (self.gx @ z) + ty * (self.gy @ z)

    def tangent_parts(self, z: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
        """``dF/dz = S + U B U^T``: sparse ``S = Tx Gx + Ty Gy``, ``U = [Gx z, Gy z]``, 2x2 ``B``."""
        tx, ty = self.tensions(z)
        U = np.column_stack([self.gx @ z, self.gy @ z])
        B = (self.stretch_gain * self.C / self.area) * np.array([[1.0, self.nu], [self.nu, 1.0]])
        return (tx * self.gx + ty * self.gy).tocsr(), U, B

    def tangent(self, z: np.ndarray) -> np.ndarray:
        """Exact tangent ``dF/dz`` as a dense matrix (for checks; use :meth:`tangent_parts`)."""
        S, U, B = self.tangent_parts(z)
        return S.toarray() + U @ B @ U.T

    def tangent_solver(self, z: np.ndarray, S0, ck: float):
        """Solver of ``(S0 + ck dF/dz) dz = r``: sparse LU plus a rank-2 Woodbury correction."""
        S, U, B = self.tangent_parts(z)
        lu = spla.splu((S0 + ck * S).tocsc())
        AU = lu.solve(U)
        cap = np.linalg.inv(ck * B) + U.T @ AU

        def solve(r):
            y = lu.solve(r)
            return y - AU @ np.linalg.solve(cap, U.T @ y)

        return solve

    def parameter_jacobian(self, z: np.ndarray, zdot: np.ndarray | None = None) -> np.ndarray:
        """``d(D z' + F(z))/d(eps0_x, eps0_y, viscous_scale, kelvin_voigt_scale)``, shape ``(n, 4)``.

        The prestrains enter the tensions (``dTx/deps0_x = C``, ``dTy/deps0_x = C nu``) and the
        Kelvin–Voigt term; the damping scales enter ``D`` linearly.
        """
        gz, hz = self.gx @ z, self.gy @ z
        C, nu, mat, p = self.C, self.nu, self.problem.material, self.params
        out = np.zeros((self.n, 4))
        out[:, 0] = C * (gz + nu * hz)
        out[:, 1] = C * (nu * gz + hz)
        if zdot is not None:
            gv, hv = self.gx @ zdot, self.gy @ zdot
            kv = p.kelvin_voigt_scale * mat.kelvin_voigt
            out[:, 0] += kv * C * (gv + nu * hv)
            out[:, 1] += kv * C * (nu * gv + hv)
            out[:, 2] = mat.viscous * (self.gram @ zdot)
            out[:, 3] = mat.kelvin_voigt * (self.linear_stiffness @ zdot)
        return out

    # -- statics --------------------------------------------------------------------------------
    def static(self, p: np.ndarray, tol: float = 1e-12, max_iter: int = 100) -> np.ndarray:
        """Equilibrium ``F(z) = p`` for a force vector ``p``, by Newton on the two tensions.

        ``z(Tx, Ty) = (Tx Gx + Ty Gy)^-1 p`` is diagonal in the separable modes, so the
        equilibrium is two scalar equations ``T = T(z(T))``. Works without prestrain too.
        """
        m = self.modes
        pq = m.to_modal_force(self.check_load(p))
        C, nu, A, par = self.C, self.nu, self.area, self.params

        def resid(T):
            k = T[0] * m.lam_x + T[1] * m.lam_y
            q = pq / k
            sx, sy = np.sum(m.lam_x * q * q) / (2 * A), np.sum(m.lam_y * q * q) / (2 * A)
            ex, ey = par.eps0_x + self.stretch_gain * sx, par.eps0_y + self.stretch_gain * sy
            return np.array([C * (ex + nu * ey), C * (ey + nu * ex)]) - T, q, k

        T = np.maximum(np.array(self.prestress), 1e-3 * C)
        for _ in range(max_iter):
            r, q, k = resid(T)
            if np.max(np.abs(r)) <= tol * np.max(T):
                return m.to_field(q)
            # d s_x / d T_a = -sum lam_x q^2 lam_a / k / A
            dsx = (
                self.stretch_gain
                * np.array([-np.sum(m.lam_x * q * q * m.lam_x / k), -np.sum(m.lam_x * q * q * m.lam_y / k)])
                / A
            )
            dsy = (
                self.stretch_gain
                * np.array([-np.sum(m.lam_y * q * q * m.lam_x / k), -np.sum(m.lam_y * q * q * m.lam_y / k)])
                / A
            )
            J = C * np.array([dsx + nu * dsy, dsy + nu * dsx]) - np.eye(2)
            step = -np.linalg.solve(J, r)
            t = 1.0
            while np.any(T + t * step <= 0):
                t *= 0.5
            T = T + t * step
        raise SolverError("Berger static solve", f"no convergence in {max_iter} iterations", "reduce the load")

    def check_load(self, p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, dtype=float)
        if p.shape != (self.n,):
            raise InputError(f"load: shape {p.shape}, expected ({self.n},) force vector")
        return p
