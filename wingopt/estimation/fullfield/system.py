"""Pressure from shape: the linear-Gaussian problem of a measured deflection field for given prestrains.

A fitted deflection ``ẑ`` (coefficients on the estimator's mesh) and prestrains ``e0`` give the
membrane's internal force ``F(ẑ; e0)`` (Föppl–von Kármán, in-plane equilibrium solved). The load
``P = sum_s c_s psi_s`` balances the true deflection ``z``: ``F(z; e0) = G c`` (``G`` the shapes'
forces). Linearised about ``ẑ`` with the FvK tangent ``K_t`` (the in-plane block eliminated)::

    z = ẑ + K_t^-1 (G c - F(ẑ) - r),        r: inertia and damping forces (time-resolved mode)

so the data ``W`` at the points (basis ``B``) are linear in ``c``::

    y = W - B ẑ + B K_t^-1 (F(ẑ) + r) = A c + noise,       A = B K_t^-1 G

with a Gaussian prior on ``c`` (the load shapes' smoothness prior): posterior, evidence and the
lift in closed form. The linearisation error is second order in ``z - ẑ``: the fit ``ẑ`` is within
the noise of ``z`` (micrometres on millimetres). ``F`` and ``K_t`` are affine in the prestress, so
the prestrains enter every quantity smoothly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse.linalg as spla

from wingopt.membrane.forward import FullStructure
from wingopt.membrane.parameters import MembraneParameters, prestress_tensions

__all__ = ["PressureFromShape", "Posterior", "posterior"]


@dataclass(frozen=True, eq=False)
class Posterior:
    """The Gaussian posterior of the load-shape coefficients for one prestrain pair.

    ``c`` (m,) mean, ``precision`` (m, m), ``log_evidence`` (up to a constant shared by every prior
    and prestrain), ``chi2`` the data's chi-square at ``c``, ``data`` the number of data and
    ``effective`` the unknowns the data determine.
    """

    c: np.ndarray
    precision: np.ndarray
    log_evidence: float
    chi2: float
    data: int
    effective: float

    @property
    def chi2_per_datum(self) -> float:
        return self.chi2 / max(self.data - self.effective, 1.0)

    @property
    def inflation(self) -> float:
        """Variance factor ``max(1, chi-square per datum)``: a misfit above the noise widens the band."""
        return max(1.0, self.chi2_per_datum)

    def variance(self, g: np.ndarray) -> float:
        """Posterior variance of ``g @ c`` (inflated by the misfit)."""
        return float(self.inflation * g @ np.linalg.solve(self.precision, g))


def posterior(A: np.ndarray, y: np.ndarray, weight: np.ndarray, prior_std: np.ndarray, prior_mean=None) -> Posterior:
    """Posterior of ``y = A c + e``, ``e ~ N(0, diag(1/weight))``, ``c ~ N(prior_mean, diag(prior_std^2))``."""
    m0 = np.zeros(A.shape[1]) if prior_mean is None else np.asarray(prior_mean, float)
    r0 = y - A @ m0
    Aw = A * weight[:, None]
    H = A.T @ Aw + np.diag(1.0 / prior_std**2)
    L = np.linalg.cholesky(H)
    b = Aw.T @ r0
    d = np.linalg.solve(L.T, np.linalg.solve(L, b))
    c = m0 + d
    r = y - A @ c
    chi2 = float(r @ (weight * r))
    prior_cost = float(np.sum((d / prior_std) ** 2))
    logdet = 2.0 * np.sum(np.log(np.diag(L))) + 2.0 * np.sum(np.log(prior_std))
    eff = float(np.trace(np.linalg.solve(H, A.T @ Aw)))
    return Posterior(c, H, -0.5 * (chi2 + prior_cost) - 0.5 * logdet, chi2, int(y.size), eff)


class PressureFromShape:
    """The linearised problem ``y = A c`` of one deflection field ``z_hat`` for any prestrain pair.

    Parameters
    ----------
    fvk : FullStructure
        On the estimator's mesh (its parameters' damping is used for ``r``).
    z_hat : ndarray (n,)
        The fitted deflection about which the balance is linearised.
    basis : ndarray (P, n)
        The deflection basis at the data points.
    forces : ndarray (n, m)
        The load shapes' force vectors ``G``.
    """

    def __init__(self, fvk: FullStructure, z_hat: np.ndarray, basis: np.ndarray, forces: np.ndarray) -> None:
        self.fvk, self.z, self.basis, self.forces = fvk, np.asarray(z_hat, float), basis, forces
        self._cache: dict = {}
        # The in-plane block and the coupling do not depend on the prestrain (a uniform prestrain's
        # stress has no divergence); the w block is K_ww(0) + Tx Gx + Ty Gy. So the reduced tangent
        # S(e0) = S0 + Tx Gx + Ty Gy with S0 = K_ww(0) - K_wu K_uu^-1 K_uw, formed once (dense, n x n),
        # and so is the internal force: F(ẑ; e0) = F_nl(ẑ) + Tx Gx ẑ + Ty Gy ẑ.
        par = fvk.params
        bare = fvk.with_params(MembraneParameters(0.0, 0.0, par.viscous_scale, par.kelvin_voigt_scale))
        n = fvk.n
        u, v = bare.inplane(self.z)
        K = bare.tangent(self.z, u, v).tocsc()
        kwu = K[:n, n:]
        coupled = spla.splu(K[n:, n:].tocsc()).solve(kwu.T.toarray())
        self._s0 = K[:n, :n].toarray() - kwu @ coupled
        self._gx, self._gy = fvk.gx.toarray(), fvk.gy.toarray()
        self._fnl = bare.force(self.z)

    @property
    def mass(self) -> np.ndarray:
        """The deflection's mass matrix ``rho h M`` (dense, n x n)."""
        m = self.fvk.mass
        return m.toarray() if hasattr(m, "toarray") else np.asarray(m)

    def tangent(self, prestrain) -> np.ndarray:
        """The reduced FvK tangent about ``z_hat`` at ``prestrain`` (dense, n x n): the load's stiffening included."""
        par = self.fvk.params
        e = MembraneParameters(float(prestrain[0]), float(prestrain[1]), par.viscous_scale, par.kelvin_voigt_scale)
        tx, ty = prestress_tensions(self.fvk.problem.material, e)
        return self._s0 + tx * self._gx + ty * self._gy

    def at(self, prestrain: tuple[float, float]):
        """``(A, offset, solve, S, s, fvk)`` at ``prestrain``: ``y = W - B ẑ + offset``, ``solve(rhs)`` the
        reduced ``K_t^-1 rhs``, ``S = K_t^-1 G``, ``s = K_t^-1 F(ẑ)`` and the membrane at ``prestrain``."""
        key = (float(prestrain[0]), float(prestrain[1]))
        if key in self._cache:
            return self._cache[key]
        par = self.fvk.params
        fvk = self.fvk.with_params(MembraneParameters(key[0], key[1], par.viscous_scale, par.kelvin_voigt_scale))
        tx, ty = fvk.prestress
        factor = sla.cho_factor(self._s0 + tx * self._gx + ty * self._gy, check_finite=False)

        def solve(rhs: np.ndarray) -> np.ndarray:
            return sla.cho_solve(factor, np.asarray(rhs, float), check_finite=False)

        force = self._fnl + tx * (self._gx @ self.z) + ty * (self._gy @ self.z)
        X = solve(np.column_stack([self.forces, force]))
        out = (self.basis @ X[:, :-1], self.basis @ X[:, -1], solve, X[:, :-1], X[:, -1], fvk)
        if len(self._cache) > 64:
            self._cache.clear()
        self._cache[key] = out
        return out

    def deflection(self, prestrain, c: np.ndarray) -> np.ndarray:
        """The deflection of the linearised balance, ``ẑ + K_t^-1 (G c - F(ẑ))``."""
        _, _, _, S, s, _ = self.at(prestrain)
        return self.z - s + S @ c
