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
reduced force ``F(w) = R_w(w, u(w), v(w))`` is integrated by :func:`~wingopt.membrane.fvk_sim.simulate_fvk`
(exponential integrator) or :func:`~wingopt.membrane.nonlinear.integrate` (generalised-alpha; its
Newton matrix is the exact Schur complement, solved as one sparse coupled system).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from wingopt.errors import InputError, SolverError
from wingopt.fe import gauss_legendre
from wingopt.membrane.model import MembraneModel
from wingopt.membrane.nonlinear import MembraneParameters, PrestressedOperators, membrane_stiffness

__all__ = ["FvKMembrane", "StaticSolution", "PointOperators"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class PointOperators:
    """A tensor space's basis at the tensor grid of Gauss points: fields, weak forms, matrices.

    The points are ``(xq_i, yq_j)`` with ``j`` fastest. Fields and weak-form vectors are
    evaluated by sum factorisation (``B1x Z B0y^T``: small dense products). Matrices of forms
    ``∫ c(x) d_a(phi) d_b(phi)^T`` with point coefficients ``c`` are assembled element by element
    as one dense product (the local splines are the same on every element of a uniform mesh) and
    one scatter, like :func:`wingopt.fe.assemble` but for coefficients that vary in the element.
    """

    space: object
    x: tuple[np.ndarray, np.ndarray]  # 1-D values and slopes at the x points, (nqx, nx)
    y: tuple[np.ndarray, np.ndarray]
    weights: np.ndarray
    order: int

    @classmethod
    def build(cls, space, order: int = 5) -> PointOperators:
        t, wt = gauss_legendre(order)
        mats, wts = [], []
        for b in (space.bx, space.by):
            xq = ((np.arange(b.n_elements)[:, None] + t[None, :]) * b.h).ravel()
            mats.append((b.matrix(xq, 0).toarray(), b.matrix(xq, 1).toarray()))
            wts.append(np.tile(wt * b.h, b.n_elements))
        return cls(space, mats[0], mats[1], np.outer(wts[0], wts[1]).ravel(), order)

    @property
    def shape(self) -> tuple[int, int]:
        return self.space.shape

    def gradient(self, coef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(f_x, f_y)`` at all points of the field with coefficients ``coef``."""
        Z = coef.reshape(self.shape)
        return (self.x[1] @ Z @ self.y[0].T).ravel(), (self.x[0] @ Z @ self.y[1].T).ravel()

    def divergence(self, ax: np.ndarray, ay: np.ndarray) -> np.ndarray:
        """``∫ (a_x phi_x + a_y phi_y)`` for point data ``a_x, a_y`` already multiplied by the weights."""
        nq = (self.x[0].shape[0], self.y[0].shape[0])
        return (self.x[1].T @ ax.reshape(nq) @ self.y[0] + self.x[0].T @ ay.reshape(nq) @ self.y[1]).ravel()

    @cached_property
    def _local(self):
        """Local products ``P_ab[q, (i, j)]`` of the 16 element splines, and the scatter indices."""
        sp_, o = self.space, self.order
        t, _ = gauss_legendre(o)
        vals = {}
        for d in ((1, 0), (0, 1)):  # d/dx, d/dy of the 16 local functions at the o*o points
            vx, vy = sp_.bx.local_values(None, t, d[0]), sp_.by.local_values(None, t, d[1])
            vals[d] = np.einsum("pa,qb->pqab", vx, vy).reshape(o * o, 16)
        keys = {"x": (1, 0), "y": (0, 1)}
        prod = {
            a + b: np.einsum("qi,qj->qij", vals[keys[a]], vals[keys[b]]).reshape(o * o, 256) for a in "xy" for b in "xy"
        }
        ex, ey = np.meshgrid(np.arange(sp_.bx.n_elements), np.arange(sp_.by.n_elements), indexing="ij")
        dofs = sp_.local_dofs(ex.ravel(), ey.ravel())
        rows, cols = np.repeat(dofs, 16, axis=1).ravel(), np.tile(dofs, (1, 16)).ravel()
        return prod, rows, cols

    def matrix(self, *terms: tuple[str, np.ndarray]) -> sp.csr_matrix:
        """``Σ ∫ c d_a(phi) d_b(phi)^T`` for terms ``("xy", c)`` etc.: ``a, b`` in ``x, y``, ``c`` at the points."""
        prod, rows, cols = self._local
        nex, ney, o = self.space.bx.n_elements, self.space.by.n_elements, self.order
        local = 0.0
        for ab, c in terms:
            cw = (np.broadcast_to(c, self.weights.shape) * self.weights).reshape(nex, o, ney, o)
            local = local + cw.transpose(0, 2, 1, 3).reshape(nex * ney, o * o) @ prod[ab]
        n_full = self.space.n_full
        full = sp.csr_matrix((local.ravel(), (rows, cols)), shape=(n_full, n_full))
        T = self.space.transform
        return (T.T @ full @ T).tocsr()


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
        self.linear = MembraneModel.from_problem(problem, nodes)
        self.problem = self.linear.problem
        self.params = MembraneParameters.nominal(problem) if params is None else params
        self.space = self.linear.space
        self.n = self.space.n
        mat = self.problem.material
        self.C, self.nu = membrane_stiffness(mat), mat.poisson_ratio
        self.ops = PointOperators.build(self.space, order)

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
        return K, spla.splu(K)

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

    def tangent_solver(self, z: np.ndarray, S, ck: float):
        """Solver of ``(S + ck dF/dw) dz = r``: the coupled system with ``u, v`` (exact Schur complement)."""
        u, v = self.inplane(z)
        n = self.n
        K = ck * self.tangent(z, u, v)
        A = (K + sp.block_diag([S, sp.csr_matrix((2 * n, 2 * n))])).tocsc()
        lu = spla.splu(A)
        return lambda r: lu.solve(np.concatenate([r, np.zeros(2 * n)]))[:n]

    # -- statics --------------------------------------------------------------------------------
    def static(
        self, p: np.ndarray, z0: np.ndarray | None = None, tol: float = 1e-11, max_iter: int = 60
    ) -> StaticSolution:
        """Equilibrium ``F(w) = p`` (``p`` a force vector, e.g. ``gram @ f``) by Newton on ``(w, u, v)``.

        The start (unless ``z0``) is the uniform-tension (Berger-type) solution, found by a
        fixed point on the two tensions; it also works without prestrain, where the linear
        stiffness vanishes. Newton steps are damped by backtracking on the total potential
        ``U - p.w`` (the equilibrium is its minimum), which makes the solve robust for large loads.
        """
        n = self.n
        p = np.asarray(p, dtype=float)
        if p.shape != (n,):
            raise InputError(f"load: shape {p.shape}, expected ({n},) force vector (e.g. gram @ coefficients)")
        z = self._berger_start(p) if z0 is None else np.asarray(z0, float)
        u, v = self.inplane(z)
        scale = max(np.linalg.norm(p), 1e-300)
        potential = self.energy(z, u, v) - p @ z
        for it in range(1, max_iter + 1):
            rw, ru, rv = self.residual(z, u, v)
            r = np.concatenate([rw - p, ru, rv])
            res = np.linalg.norm(r) / scale
            step = -spla.spsolve(self.tangent(z, u, v).tocsc(), r)
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
