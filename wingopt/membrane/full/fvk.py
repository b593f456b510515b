"""High-fidelity geometrically nonlinear membrane: Föppl–von Kármán without bending (spec §8).

Unknowns: the deflection ``w`` and the in-plane displacements ``u, v``, all on the membrane's
zero-edge cubic-spline space (``u = v = w = 0`` on the frame). With prestrains ``eps0_x, eps0_y``::

    e_x = eps0_x + u_x + w_x^2/2,  e_y = eps0_y + v_y + w_y^2/2,  g = u_y + v_x + w_x w_y
    N_x = C (e_x + nu e_y),  N_y = C (e_y + nu e_x),  N_xy = C (1 - nu)/2 g,   C = E h/(1 - nu^2)

The weak forms are the first and second variations of the stored energy
``U = ∫ (N_x e_x + N_y e_y + N_xy g) / 2``. Their coefficients vary from point to point, so they
are evaluated with point operators: the sparse basis matrices ``B_x, B_y`` of the space at all
Gauss points (5 x 5 per element, exact for the degree-8 integrands), and a weak form
``∫ c(x) phi_x psi_x`` is ``B_x^T diag(c w_q) B_x``. The in-plane block is linear in ``(u, v)``
and constant; it is factorised once, so the in-plane equilibrium for a given ``w`` is one solve.

Dynamics: in-plane inertia is neglected (in-plane waves are ~100x faster), so ``u, v`` follow
``w`` quasi-statically and the out-of-plane equation ``rho h M w'' + D w' + F(w) = p`` with the
reduced force ``F(w) = R_w(w, u(w), v(w))`` is integrated by the full-order integrator
(:func:`~wingopt.membrane.full.integrator.integrate`, exponential integrator).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from wingopt.errors import InputError, SolverError
from wingopt.fe.points import PointOperators
from wingopt.membrane.full.operators import PrestressedOperators
from wingopt.membrane.model import MembraneModel
from wingopt.membrane.parameters import MembraneParameters, membrane_stiffness

__all__ = ["FvKMembrane", "StaticSolution"]

log = logging.getLogger(__name__)


CHORD_RATE = 4.0
"""Least residual reduction per step for which :meth:`FvKMembrane.static` keeps a tangent's factors."""


@dataclass(frozen=True, eq=False)
class StaticSolution:
    """Static equilibrium: deflection ``z`` and in-plane ``u, v`` coefficients, Newton count."""

    z: np.ndarray
    u: np.ndarray
    v: np.ndarray
    iterations: int
    residual: float


class FvKMembrane(PrestressedOperators):
    """Föppl–von Kármán membrane on the linear model's mesh and spline space.

    Parameters
    ----------
    problem : MembraneProblem
    nodes : (int, int), optional
        Mesh (default: the problem's).
    params : MembraneParameters, optional
        Prestrains and damping factors (default: the problem file's).
    order : int
        Gauss points per direction and element (5 integrates the nonlinear forms exactly).
    """

    def __init__(self, problem, nodes=None, params: MembraneParameters | None = None, order: int = 5) -> None:
        self._setup(MembraneModel.from_problem(problem, nodes), params, order)

    @classmethod
    def from_model(cls, model: MembraneModel, params: MembraneParameters | None = None, order: int = 5) -> FvKMembrane:
        """The FvK membrane on a linear model's mesh (its space, Gram and sensors are shared)."""
        self = cls.__new__(cls)
        self._setup(model, params, order)
        return self

    def _setup(self, model: MembraneModel, params: MembraneParameters | None, order: int) -> None:
        self.linear = model
        self.problem = model.problem
        self.params = MembraneParameters.nominal(self.problem) if params is None else params
        self.space = model.space
        self.n = self.space.n
        mat = self.problem.material
        self.C, self.nu = membrane_stiffness(mat), mat.poisson_ratio
        self.area = self.problem.width * self.problem.height
        self.rho_h = mat.areal_density
        self.ops = PointOperators.build(self.space, order)

    def with_params(self, params: MembraneParameters) -> FvKMembrane:
        """The same operators with other parameters (the in-plane factorisation is shared)."""
        other = FvKMembrane.__new__(FvKMembrane)
        other.__dict__.update(self.__dict__)
        other.params = params
        for key in ("damping", "linear_stiffness"):
            other.__dict__.pop(key, None)
        return other

    stretch_gain = 1.0
    """The uniform-tension part of the tangent is Berger's at gain 1 (the integrator's Newton matrix)."""

    def remainder(self, q: np.ndarray) -> np.ndarray:
        """Modal ``V^T N(V q)``: the FvK force less its prestress part (separable modes)."""
        m = self.modes
        return (
            m.to_modal_force(self.force(m.to_field(q)))
            - (self.prestress[0] * m.lam_x + self.prestress[1] * m.lam_y) * q
        )

    def equilibrium(self, f: np.ndarray) -> np.ndarray:
        """Static deflection under load coefficients ``f`` (the forward-model protocol)."""
        return self.static(self.gram @ np.asarray(f, float)).z

    # -- linear operators -------------------------------------------------------------------

    @cached_property
    def _inplane(self):
        """Constant in-plane stiffness ``K_uu`` (2n x 2n) and its LU factors."""
        o, C, nu = self.ops, self.C, self.nu
        G = 0.5 * C * (1 - nu)
        kuu = o.matrix(("xx", C), ("yy", G))
        kvv = o.matrix(("yy", C), ("xx", G))
        kuv = o.matrix(("xy", C * nu), ("yx", G))
        K = sp.bmat([[kuu, kuv], [kuv.T, kvv]]).tocsc()
        # K is symmetric: a symmetric fill-reducing ordering (minimum degree on K + K^T) leaves ~30 %
        # fewer factor entries than SuperLU's default COLAMD on these 2-D meshes, and the solve below
        # runs at every force evaluation of the FvK truth (~3.6 per time step): ~1.8x faster solves.
        return K, spla.splu(K, permc_spec="MMD_AT_PLUS_A")

    # -- strains, stresses, residuals -------------------------------------------------------
    def _fields(self, z, u, v):
        o = self.ops
        wx, wy = o.gradient(z)
        ux, uy = o.gradient(u)
        vx, vy = o.gradient(v)
        ex = self.params.eps0_x + ux + 0.5 * wx * wx
        ey = self.params.eps0_y + vy + 0.5 * wy * wy
        g = uy + vx + wx * wy
        nx, ny = self.C * (ex + self.nu * ey), self.C * (ey + self.nu * ex)
        nxy = 0.5 * self.C * (1 - self.nu) * g
        return wx, wy, ex, ey, g, nx, ny, nxy

    def stress_resultants(self, z, u, v, x, y) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``N_x, N_y, N_xy`` (N/m) at points ``(x, y)``."""
        sp_ = self.space
        wx, wy = sp_.evaluate(z, x, y, 1, 0), sp_.evaluate(z, x, y, 0, 1)
        ex = self.params.eps0_x + sp_.evaluate(u, x, y, 1, 0) + 0.5 * wx**2
        ey = self.params.eps0_y + sp_.evaluate(v, x, y, 0, 1) + 0.5 * wy**2
        g = sp_.evaluate(u, x, y, 0, 1) + sp_.evaluate(v, x, y, 1, 0) + wx * wy
        return self.C * (ex + self.nu * ey), self.C * (ey + self.nu * ex), 0.5 * self.C * (1 - self.nu) * g

    def residual(self, z, u, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """First variation of the stored energy: ``(R_w, R_u, R_v)``."""
        wx, wy, _, _, _, nx, ny, nxy = self._fields(z, u, v)
        o, W = self.ops, self.ops.weights
        rw = o.divergence(W * (nx * wx + nxy * wy), W * (nxy * wx + ny * wy))
        return rw, o.divergence(W * nx, W * nxy), o.divergence(W * nxy, W * ny)

    def energy(self, z, u, v) -> float:
        """Stored energy ``∫ (N_x e_x + N_y e_y + N_xy g)/2`` (J), prestress included."""
        _, _, ex, ey, g, nx, ny, nxy = self._fields(z, u, v)
        return float(0.5 * np.sum(self.ops.weights * (nx * ex + ny * ey + nxy * g)))

    def tangent(self, z, u, v) -> sp.csr_matrix:
        """Second variation: the symmetric ``(3n, 3n)`` tangent on ``[w; u; v]``.

        Material part ``E^T C E`` with the strain rows ``e_x = [w_x d_x, d_x, 0]``,
        ``e_y = [w_y d_y, 0, d_y]``, ``g = [w_y d_x + w_x d_y, d_y, d_x]``, plus the geometric
        part ``∫ (N_x w_x w_x + N_y w_y w_y + N_xy (w_x w_y + w_y w_x))`` in the ``w`` block.
        """
        o, C, nu = self.ops, self.C, self.nu
        G = 0.5 * C * (1 - nu)
        wx, wy, _, _, _, nx, ny, nxy = self._fields(z, u, v)
        cxy = (C * nu + G) * wx * wy + nxy
        kww = o.matrix(
            ("xx", C * wx * wx + G * wy * wy + nx), ("yy", C * wy * wy + G * wx * wx + ny), ("xy", cxy), ("yx", cxy)
        )
        kwu = o.matrix(("xx", C * wx), ("yy", G * wx), ("xy", G * wy), ("yx", C * nu * wy))
        kwv = o.matrix(("yy", C * wy), ("xx", G * wy), ("xy", C * nu * wx), ("yx", G * wx))
        kin = self._inplane[0]
        n = self.n
        return sp.bmat([[kww, kwu, kwv], [kwu.T, kin[:n, :n], kin[:n, n:]], [kwv.T, kin[n:, :n], kin[n:, n:]]]).tocsr()

    # -- the reduced out-of-plane model (in-plane equilibrium eliminated) --------------------
    def _inplane_rhs(self, wx: np.ndarray, wy: np.ndarray) -> np.ndarray:
        """``[R_u; R_v]`` at ``u = v = 0`` (the prestress part integrates to zero on the frame)."""
        C, nu, W = self.C, self.nu, self.ops.weights
        ex0, ey0 = self.params.eps0_x + 0.5 * wx * wx, self.params.eps0_y + 0.5 * wy * wy
        nx, ny, nxy = C * (ex0 + nu * ey0), C * (ey0 + nu * ex0), 0.5 * C * (1 - nu) * wx * wy
        o = self.ops
        return np.concatenate([o.divergence(W * nx, W * nxy), o.divergence(W * nxy, W * ny)])

    def inplane(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """In-plane equilibrium ``(u, v)`` for a deflection ``z`` (one solve with the constant ``K_uu``)."""
        uv = -self._inplane[1].solve(self._inplane_rhs(*self.ops.gradient(z)))
        return uv[: self.n], uv[self.n :]

    def force(self, z: np.ndarray) -> np.ndarray:
        """Out-of-plane internal force ``F(w) = R_w(w, u(w), v(w))`` (N, coefficient space)."""
        o, C, nu, W = self.ops, self.C, self.nu, self.ops.weights
        wx, wy = o.gradient(z)
        uv = -self._inplane[1].solve(self._inplane_rhs(wx, wy))
        ux, uy = o.gradient(uv[: self.n])
        vx, vy = o.gradient(uv[self.n :])
        ex = self.params.eps0_x + ux + 0.5 * wx * wx
        ey = self.params.eps0_y + vy + 0.5 * wy * wy
        nx, ny, nxy = C * (ex + nu * ey), C * (ey + nu * ex), 0.5 * C * (1 - nu) * (uy + vx + wx * wy)
        return o.divergence(W * (nx * wx + nxy * wy), W * (nxy * wx + ny * wy))

    # -- statics --------------------------------------------------------------------------------
    def static(
        self,
        p: np.ndarray,
        z0: np.ndarray | None = None,
        tol: float = 1e-11,
        max_iter: int = 60,
        reuse_tangent: bool = False,
    ) -> StaticSolution:
        """Equilibrium ``F(w) = p`` (``p`` a force vector, e.g. ``gram @ f``) by Newton on ``(w, u, v)``.

        The start (unless ``z0``) is the uniform-tension (Berger-type) solution, found by a
        fixed point on the two tensions; it also works without prestrain, where the linear
        stiffness vanishes. Newton steps are damped by backtracking on the total potential
        ``U - p.w`` (the equilibrium is its minimum), which makes the solve robust for large loads.
        With ``reuse_tangent`` the tangent's factors are kept while each step cuts the residual at
        least :data:`CHORD_RATE`-fold (modified Newton: from a close start, the same equilibrium for
        one factorisation instead of one per step).
        """
        n = self.n
        p = np.asarray(p, dtype=float)
        if p.shape != (n,):
            raise InputError(f"load: shape {p.shape}, expected ({n},) force vector (e.g. gram @ coefficients)")
        z = self._berger_start(p) if z0 is None else np.asarray(z0, float)
        u, v = self.inplane(z)
        scale = max(np.linalg.norm(p), 1e-300)
        potential = self.energy(z, u, v) - p @ z
        lu, last = None, np.inf
        for it in range(1, max_iter + 1):
            rw, ru, rv = self.residual(z, u, v)
            r = np.concatenate([rw - p, ru, rv])
            res = np.linalg.norm(r) / scale
            if not reuse_tangent:
                step = -spla.spsolve(self.tangent(z, u, v).tocsc(), r)
            else:
                if lu is None or res > last / CHORD_RATE:  # no factors yet, or they no longer converge fast
                    lu = spla.splu(self.tangent(z, u, v).tocsc())
                step, last = -lu.solve(r), res
            t = 1.0
            while True:
                zt, ut, vt = z + t * step[:n], u + t * step[n : 2 * n], v + t * step[2 * n :]
                pt = self.energy(zt, ut, vt) - p @ zt
                if pt <= potential + 1e-14 * abs(potential) or t < 1e-4:
                    break
                t *= 0.5
            z, u, v, potential = zt, ut, vt, pt
            if np.max(np.abs(step[:n])) * t <= tol * np.max(np.abs(z)):
                rw, ru, rv = self.residual(z, u, v)
                res = np.linalg.norm(np.concatenate([rw - p, ru, rv])) / scale
                return StaticSolution(z, u, v, it, float(res))
        raise SolverError(
            "FvK static solve",
            f"Newton did not converge in {max_iter} iterations (residual {res:.2e})",
            "reduce the load or refine the mesh",
        )

    def _berger_start(self, p: np.ndarray) -> np.ndarray:
        """Uniform-tension solution: fixed point ``T <- T(mean stretch of z(T))`` (geometric mean for stability)."""
        A = self.problem.width * self.problem.height
        tx0, ty0 = self.prestress
        C, nu = self.C, self.nu
        tx = ty = max(tx0, ty0, 1e-3 * C)
        for _ in range(200):
            z = spla.spsolve((tx * self.gx + ty * self.gy).tocsc(), p)
            sx, sy = z @ (self.gx @ z) / (2 * A), z @ (self.gy @ z) / (2 * A)
            nx = C * (self.params.eps0_x + sx + nu * (self.params.eps0_y + sy))
            ny = C * (self.params.eps0_y + sy + nu * (self.params.eps0_x + sx))
            nx, ny = np.sqrt(tx * max(nx, 1e-12 * C)), np.sqrt(ty * max(ny, 1e-12 * C))
            if abs(nx - tx) <= 1e-6 * tx and abs(ny - ty) <= 1e-6 * ty:
                break
            tx, ty = nx, ny
        return z
