"""Test support: an independent implicit integrator (generalised-alpha, Chung & Hulbert 1993).

The package integrates the full-order membranes with one exponential integrator
(:func:`wingopt.membrane.full.integrator.integrate`); this Newton-based generalised-alpha scheme
with the exact coupled tangent is the independent cross-check the tests hold it against. Not part
of the package: nothing but the tests uses it.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from wingopt.errors import InputError, SolverError
from wingopt.membrane.full.berger import BergerMembrane
from wingopt.membrane.full.fvk import FvKMembrane

log = logging.getLogger(__name__)


def berger_tangent_solver(self, z: np.ndarray, S0, ck: float):
    """Solver of ``(S0 + ck dF/dz) dz = r``: sparse LU plus a rank-2 Woodbury correction."""
    S, U, B = self.tangent_parts(z)
    lu = spla.splu((S0 + ck * S).tocsc())
    AU = lu.solve(U)
    cap = np.linalg.inv(ck * B) + U.T @ AU

    def solve(r):
        y = lu.solve(r)
        return y - AU @ np.linalg.solve(cap, U.T @ y)

    return solve


def fvk_tangent_solver(self, z: np.ndarray, S, ck: float):
    """Solver of ``(S + ck dF/dw) dz = r``: the coupled system with ``u, v`` (exact Schur complement)."""
    u, v = self.inplane(z)
    n = self.n
    K = ck * self.tangent(z, u, v)
    A = (K + sp.block_diag([S, sp.csr_matrix((2 * n, 2 * n))])).tocsc()
    lu = spla.splu(A)
    return lambda r: lu.solve(np.concatenate([r, np.zeros(2 * n)]))[:n]


def tangent_solver(model, z, S, ck):
    """Solver of ``(S + ck dF/dz) dz = r`` for a Berger, FvK or linear structure."""
    if isinstance(model, BergerMembrane):
        return berger_tangent_solver(model, z, S, ck)
    if isinstance(model, FvKMembrane):
        return fvk_tangent_solver(model, z, S, ck)
    return model.tangent_solver(z, S, ck)


@dataclass(frozen=True)
class AlphaSettings:
    """Generalised-alpha time stepping.

    Attributes
    ----------
    dt : float
        Output sample period (s).
    substeps : int
        Integration steps per sample.
    rho_inf : float
        Spectral radius at infinite frequency, in ``[0, 1]``: 1 is the (non-dissipative)
        trapezoidal rule, smaller values damp the unresolved high modes; second order for all.
    tol : float
        Newton stops when ``max|dz| <= tol * max|z|``.
    max_iter : int
        Newton iterations per step (the tangent is refreshed when convergence slows).
    """

    dt: float = 1.0e-3
    substeps: int = 1
    rho_inf: float = 0.9
    tol: float = 1.0e-10
    max_iter: int = 40

    def __post_init__(self) -> None:
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise InputError(f"dt = {self.dt!r}: expected a positive sample period (s)")
        if not (isinstance(self.substeps, (int, np.integer)) and self.substeps >= 1):
            raise InputError(f"substeps = {self.substeps!r}: expected an integer >= 1")
        if not (0.0 <= self.rho_inf <= 1.0):
            raise InputError(f"rho_inf = {self.rho_inf!r}: expected a number in [0, 1]")


def alpha_coefficients(rho_inf: float) -> tuple[float, float, float, float]:
    """``alpha_m, alpha_f, gamma, beta`` of Chung & Hulbert's generalised-alpha method."""
    am = (2 * rho_inf - 1) / (rho_inf + 1)
    af = rho_inf / (rho_inf + 1)
    gamma = 0.5 - am + af
    beta = 0.25 * (1 - am + af) ** 2
    return am, af, gamma, beta


class NonlinearStructure(Protocol):
    """What :func:`integrate` needs: ``mass @ a + damping @ v + force(z) = p``."""

    n: int
    mass: sp.spmatrix
    damping: sp.spmatrix

    def force(self, z: np.ndarray) -> np.ndarray: ...

    def tangent_solver(self, z: np.ndarray, S: sp.spmatrix, ck: float) -> Callable[[np.ndarray], np.ndarray]:
        """A solver of ``(S + ck K_t(z)) dz = r``, ``K_t = dF/dz``."""
        ...


@dataclass(frozen=True, eq=False)
class LinearStructure:
    """``M a + D v + K z = p``: the linear model in the :class:`NonlinearStructure` interface."""

    mass: sp.spmatrix
    damping: sp.spmatrix
    stiffness: sp.spmatrix

    @property
    def n(self) -> int:
        return self.mass.shape[0]

    def force(self, z: np.ndarray) -> np.ndarray:
        return self.stiffness @ z

    def tangent_solver(self, z, S, ck):
        return spla.factorized((S + ck * self.stiffness).tocsc())


@dataclass(frozen=True, eq=False)
class AlphaResult:
    """Sampled response: times ``(N+1,)``, deflection and velocity coefficients ``(N+1, n)``."""

    t: np.ndarray
    z: np.ndarray
    zdot: np.ndarray
    newton_iterations: int
    factorizations: int


def integrate(
    structure: NonlinearStructure,
    load: Callable[[float], np.ndarray],
    t_end: float,
    z0: np.ndarray,
    v0: np.ndarray | None = None,
    settings: AlphaSettings = AlphaSettings(),
) -> AlphaResult:
    """Integrate ``M a + D v + F(z) = p(t)`` from ``(z0, v0)`` by generalised-alpha and Newton.

    ``load(t)`` returns the force vector ``p`` (not load coefficients). The equilibrium is taken
    at the generalised mid-point, ``M a_{1-am} + D v_{1-af} + F(z_{1-af}) = p(t_{1-af})``. Newton
    reuses the factorised tangent while it contracts fast (modified Newton) and refreshes it
    otherwise.
    """
    if not (np.isfinite(t_end) and t_end > 0):
        raise InputError(f"t_end = {t_end!r}: expected a positive duration (s)")
    s = settings
    samples = int(round(t_end / s.dt))
    if samples < 1:
        raise InputError(f"t_end = {t_end!r}: shorter than one sample (dt = {s.dt})")
    h = s.dt / s.substeps
    am, af, gam, beta = alpha_coefficients(s.rho_inf)
    M, D = structure.mass, structure.damping
    z = np.array(z0, dtype=float)
    v = np.zeros_like(z) if v0 is None else np.array(v0, dtype=float)
    a = spla.spsolve(sp.csc_matrix(M), load(0.0) - D @ v - structure.force(z))
    S = ((1 - am) / (beta * h * h) * M + (1 - af) * gam / (beta * h) * D).tocsc()
    ck = 1.0 - af
    Z, V = np.empty((samples + 1, z.size)), np.empty((samples + 1, z.size))
    Z[0], V[0] = z, v
    solver, iters, facts = None, 0, 0
    eta = 1.0  # contraction estimate theta/(1-theta), carried from step to step
    for k in range(samples):
        for j in range(s.substeps):
            t0 = (k * s.substeps + j) * h
            pf = load(t0 + (1 - af) * h)
            z1 = z + h * v + 0.5 * h * h * a
            prev = np.inf
            eta = max(eta, 1e-3) ** 0.8  # first iterate of a step: trust the last rate a little less
            for it in range(s.max_iter):
                a1 = (z1 - z - h * v - h * h * (0.5 - beta) * a) / (beta * h * h)
                v1 = v + h * ((1 - gam) * a + gam * a1)
                zf = (1 - af) * z1 + af * z
                r = M @ ((1 - am) * a1 + am * a) + D @ ((1 - af) * v1 + af * v) + structure.force(zf) - pf
                if solver is None:
                    solver, facts = tangent_solver(structure, zf, S, ck), facts + 1
                dz = solver(-r)
                z1 = z1 + dz
                iters += 1
                size = np.max(np.abs(dz))
                if it > 0:
                    theta = size / prev
                    eta = theta / (1.0 - theta) if theta < 1.0 else np.inf
                # Stop when the error left after this update, estimated from the contraction rate
                # (Hairer & Wanner, Solving ODEs II, IV.8), is below the tolerance.
                if eta * size <= s.tol * max(np.max(np.abs(z1)), 1e-300):
                    break
                if it > 0 and (theta > 0.3 or it >= 6):
                    solver = None  # slow contraction: refresh the tangent at the next iterate
                prev = size
            else:
                raise SolverError(
                    "generalised-alpha", f"Newton did not converge at t = {t0:.4g} s (dt = {h:g})", "reduce dt"
                )
            a_new = (z1 - z - h * v - h * h * (0.5 - beta) * a) / (beta * h * h)
            v = v + h * ((1 - gam) * a + gam * a_new)
            z, a = z1, a_new
        Z[k + 1], V[k + 1] = z, v
    log.debug("generalised-alpha: %d samples, %d Newton iterations, %d factorisations", samples, iters, facts)
    return AlphaResult(np.arange(samples + 1) * s.dt, Z, V, iters, facts)
