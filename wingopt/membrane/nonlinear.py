"""Shared pieces of the geometrically nonlinear membrane models (spec §8).

* :class:`MembraneParameters` — the identifiable parameters: prestrains ``eps0_x, eps0_y`` and
  scale factors of the two damping terms.
* :class:`AlphaSettings` and :func:`integrate` — an implicit generalised-alpha integrator
  (Chung & Hulbert 1993) with Newton iterations for ``M a + D v + F(z) = p(t)``, for any model
  with ``force`` and ``tangent_solver`` (FvK, Berger, :class:`LinearStructure`). The records use
  the more accurate exponential integrators (:mod:`~wingopt.membrane.fvk_sim`,
  :mod:`~wingopt.membrane.berger_sim`); this one is the independent cross-check.

Damping (both nonlinear models): ``D = s_v gamma M + s_kv eta K_T0`` with
``K_T0 = Tx0 Gx + Ty0 Gy`` the linear tension matrix of the *prestress* (``Tx0, Ty0`` from
``eps0_x, eps0_y``), ``Gx = ∫ phi_x phi_x^T``, ``Gy = ∫ phi_y phi_y^T``. It is the linear model's
damping (spec §2) for that prestrain and does not follow the deflection-induced tension: the
damping stays linear, so the small-load limit is the linear model exactly and the damping scales
enter the equations linearly.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Protocol

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from wingopt.errors import InputError, SolverError

__all__ = [
    "PrestressedOperators",
    "MembraneParameters",
    "AlphaSettings",
    "NonlinearStructure",
    "LinearStructure",
    "AlphaResult",
    "integrate",
    "alpha_coefficients",
]

log = logging.getLogger(__name__)


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


class PrestressedOperators:
    """The operators every nonlinear membrane shares: Grams of the slopes, prestress, damping.

    Mixed into :class:`~wingopt.membrane.berger.BergerMembrane` and
    :class:`~wingopt.membrane.fvk.FvKMembrane`, which set ``linear`` (the linear
    :class:`~wingopt.membrane.MembraneModel` of the mesh), ``space``, ``problem`` and ``params``.
    """

    @cached_property
    def gx(self) -> sp.csr_matrix:
        """``Gx = ∫ phi_x phi_x^T`` (Kronecker product of 1-D Grams)."""
        sx = self.space
        return sp.kron(sx.bx.gram(1, 1), sx.by.gram(0, 0), format="csr")

    @cached_property
    def gy(self) -> sp.csr_matrix:
        """``Gy = ∫ phi_y phi_y^T``."""
        sx = self.space
        return sp.kron(sx.bx.gram(0, 0), sx.by.gram(1, 1), format="csr")

    @property
    def gram(self) -> sp.csr_matrix:
        return self.linear.gram

    @property
    def mass(self) -> sp.csr_matrix:
        return self.linear.mass

    @property
    def prestress(self) -> tuple[float, float]:
        return prestress_tensions(self.problem.material, self.params)

    @cached_property
    def linear_stiffness(self) -> sp.csr_matrix:
        """``K_T0 = Tx0 Gx + Ty0 Gy``: the small-deflection limit of the tangent."""
        tx, ty = self.prestress
        return (tx * self.gx + ty * self.gy).tocsr()

    @cached_property
    def damping(self) -> sp.csr_matrix:
        """``s_v gamma M + s_kv eta K_T0`` (the linear model's damping at the prestress, scaled)."""
        mat, p = self.problem.material, self.params
        return (
            p.viscous_scale * mat.viscous * self.gram + p.kelvin_voigt_scale * mat.kelvin_voigt * self.linear_stiffness
        ).tocsr()


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
                    solver, facts = structure.tangent_solver(zf, S, ck), facts + 1
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
