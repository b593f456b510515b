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
sensitivities (:mod:`wingopt.membrane.full.integrator`) therefore cost O(n) per step.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from wingopt.errors import InputError, SolverError
from wingopt.membrane.full.operators import PrestressedOperators
from wingopt.membrane.model import MembraneModel
from wingopt.membrane.parameters import MembraneParameters, membrane_stiffness

__all__ = ["BergerMembrane"]


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

    # -- force and derivatives ------------------------------------------------------------------
    def remainder(self, q: np.ndarray) -> np.ndarray:
        """Modal stretch force ``(dTx(q) lx + dTy(q) ly) q``: the force less its prestress part."""
        m, C, nu, g = self.modes, self.C, self.nu, self.stretch_gain
        sx, sy = np.sum(m.lam_x * q * q) / (2 * self.area), np.sum(m.lam_y * q * q) / (2 * self.area)
        return (g * C * (sx + nu * sy) * m.lam_x + g * C * (sy + nu * sx) * m.lam_y) * q

    def equilibrium(self, f: np.ndarray) -> np.ndarray:
        """Static deflection under load coefficients ``f`` (the forward-model protocol)."""
        return self.static(self.gram @ np.asarray(f, float))

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
