"""The plate-wing FE model with piezocomposite patch pairs (chapters 4–5, spec §3).

Semi-discrete model (eqs. 5.6–5.14) in the cubic B-spline basis ``phi`` (clamped at the root
``y = L``, free elsewhere)::

    M z'' + Kd z' + K z = f + b u,        y = C z

    M  = ∫ rho_h phi phi^T                               (rho_h = rho h + 2 rho_pz h_pz, eq. 4.22)
    K  = ∫ kappa(phi) ^T D   kappa(phi)                  kappa = [phi_xx, phi_yy, 2 phi_xy] (K1+K2+K3)
    Kd = ∫ kappa(phi) ^T eta kappa(phi) + ∫ gamma phi phi^T          (Kd1+...+Kd4)
    b[:, i] = -∫_{patch i} (Mx_i phi_xx + My_i phi_yy)               (eq. 4.26, per volt)
    C[i, :] = ∫_{patch i} h (phi_xx + phi_yy)                        (eq. 4.19)

``D`` and ``eta`` are piecewise constant (skin, battens, patch pairs: :mod:`wingopt.plate.layout`).
The input ``u`` is the voltage of each patch pair (file order, PZ1..PZ9). Polarity: a positive
voltage extends the top patch and contracts the bottom one, so the pair bends its region to negative
curvature ``w_xx, w_yy < 0`` (mid-chord up for PZ1/4/7, tip down for a same-sign pair at the root):
the dissertation's reported signs (camber and bending with positive voltages, Figs. 5.25, 5.32),
which also suits the asymmetric limits of a macro-fibre composite (-500 V … +1500 V). The
first-order state is ``x = [z; z']``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from wingopt.dynamics import SecondOrderSystem
from wingopt.errors import InputError
from wingopt.fe import (
    BilinearForm,
    EdgeCondition,
    LinearForm,
    SplineBasis1D,
    TensorSpace,
    assemble,
    assemble_vector,
    project,
)
from wingopt.plate.layout import CellProperties, cell_properties
from wingopt.plate.shapes import SHAPES, target_function
from wingopt.problem.plate import PlateProblem

__all__ = ["PlateModel", "plate_space", "bending_form", "mass_form"]

log = logging.getLogger(__name__)


def plate_space(width: float, length: float, nodes: tuple[int, int]) -> TensorSpace:
    """Cubic-spline space: free at x = 0 and x = W, free at the tip y = 0, clamped at the root y = L."""
    nx, ny = nodes
    return TensorSpace(
        SplineBasis1D(width, nx - 1, EdgeCondition.FREE, EdgeCondition.FREE),
        SplineBasis1D(length, ny - 1, EdgeCondition.FREE, EdgeCondition.CLAMPED),
    )


def _curvature(u) -> tuple:
    return (u.dxx, u.dyy, 2.0 * u.dxy)


@BilinearForm
def bending_form(u, v, w):
    """``kappa(u)^T D kappa(v)`` with ``kappa = [w_xx, w_yy, 2 w_xy]`` and per-cell ``w.D`` (3x3)."""
    ku, kv = _curvature(u), _curvature(v)
    # Contract D with kappa(u) first (cheap, no j axis), then three full products.
    dku = [sum(w.D[..., a, b] * ku[a] for a in range(3)) for b in range(3)]
    return sum(dku[b] * kv[b] for b in range(3))


@BilinearForm
def mass_form(u, v, w):
    """``rho_h phi phi^T`` with per-cell ``w.rho``."""
    return w.rho * u.value * v.value


# Minus: positive voltage = moment towards negative curvature (see the module docstring).
_actuation_form = LinearForm(lambda v, w: -(w.mx * v.dxx + w.my * v.dyy))
_sensing_form = LinearForm(lambda v, w: w.h * (v.dxx + v.dyy))


@dataclass(frozen=True, eq=False)
class PlateModel:
    """Assembled operators of a plate problem on one mesh.

    Attributes
    ----------
    problem : PlateProblem
    space : TensorSpace
        Coefficients ordered with the y index fastest (``k = m * ny + n``).
    properties : CellProperties
        Per-cell material data (regions, patches, rigidities).
    gram : sparse (n, n)
        ``S = ∫ phi phi^T`` (projections, eq. 5.16).
    mass, stiffness, damping : sparse (n, n)
        ``M``, ``K``, ``Kd`` of eq. 5.6 (symmetric; ``M`` and ``K`` positive definite).
    actuation : ndarray (n, m)
        ``b``: generalized force per volt of each patch pair (columns in patch order); positive
        voltage bends the patch region to negative curvature (top face in extension).
    sensing : ndarray (m, n)
        ``C``: strain output ``S_i = C[i] @ z`` of each patch (eq. 4.19), in m (strain x area / h).
    build_seconds : float
        Wall time of the assembly.
    """

    problem: PlateProblem
    space: TensorSpace
    properties: CellProperties
    gram: sp.csr_matrix
    mass: sp.csr_matrix
    stiffness: sp.csr_matrix
    damping: sp.csr_matrix
    actuation: np.ndarray
    sensing: np.ndarray
    build_seconds: float = 0.0

    @classmethod
    def from_problem(cls, problem: PlateProblem, nodes: tuple[int, int] | None = None) -> PlateModel:
        """Assemble the model of ``problem`` (on ``nodes`` instead of the problem's mesh if given).

        A problem of another kind, a malformed mesh and a mesh that cannot fit in memory
        (:func:`wingopt.resources.estimate_modes`) raise an :class:`~wingopt.errors.InputError`.
        """
        from wingopt import resources
        from wingopt.problem import as_problem

        t0 = time.perf_counter()
        problem = as_problem(problem, "plate")
        if nodes is not None:
            problem = problem.with_mesh(nodes)
        resources.check(resources.estimate_modes(problem.nodes, "plate", knob="mesh"))
        space = plate_space(problem.width, problem.length, problem.nodes)
        props = cell_properties(problem, space)
        cells = props.cells
        gram = assemble(space, mass_form, cells, data={"rho": np.ones(len(cells))})
        mass = assemble(space, mass_form, cells, data={"rho": props.areal_density})
        stiffness = assemble(space, bending_form, cells, data={"D": props.rigidity})
        damping = assemble(space, bending_form, cells, data={"D": props.viscosity}) + assemble(
            space, mass_form, cells, data={"rho": props.viscous}
        )
        m = len(problem.patches)
        b = np.zeros((space.n, m))
        C = np.zeros((m, space.n))
        for i in range(m):
            sel = np.flatnonzero(props.patch == i)
            if sel.size == 0:
                continue
            sub = cells.subset(sel)
            b[:, i] = assemble_vector(
                space, _actuation_form, sub, {"mx": props.moment_x[sel], "my": props.moment_y[sel]}
            )
            C[i] = assemble_vector(space, _sensing_form, sub, {"h": props.thickness[sel]})
        sym = [(0.5 * (A + A.T)).tocsr() for A in (gram, mass, stiffness, damping)]
        elapsed = time.perf_counter() - t0
        log.debug("plate model %dx%d: %d dofs, %d cells in %.3f s", *problem.nodes, space.n, len(cells), elapsed)
        return cls(problem, space, props, *sym, b, C, elapsed)

    # -- sizes ------------------------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of coefficients (degrees of freedom) of the deflection."""
        return self.space.n

    @property
    def n_inputs(self) -> int:
        """Number of patch pairs (inputs and outputs)."""
        return self.actuation.shape[1]

    @property
    def patch_names(self) -> tuple[str, ...]:
        return self.problem.patch_names

    def __repr__(self) -> str:
        # The dataclass repr prints the problem, the cell data and every operator (90 000 characters).
        nx, ny = self.problem.nodes
        return (
            f"PlateModel(problem={self.problem.name!r}, mesh {nx}x{ny}, dofs={self.n}, "
            f"patches={self.n_inputs}, built in {self.build_seconds:.3g} s)"
        )

    # -- dynamics ---------------------------------------------------------------------------------
    @cached_property
    def system(self) -> SecondOrderSystem:
        """``M z'' + Kd z' + K z = b u`` with ``u`` the patch voltages (V)."""
        return SecondOrderSystem(self.mass, self.damping, self.stiffness, self.actuation)

    def modes(self, count: int) -> tuple[np.ndarray, np.ndarray]:
        """Lowest ``count`` undamped frequencies (Hz) and M-orthonormal mode shapes ``(n, count)``."""
        omega, Phi = self.system.undamped_modes(count)
        return omega / (2 * np.pi), Phi

    def frequencies_hz(self, count: int) -> np.ndarray:
        """Lowest undamped natural frequencies, Hz."""
        return self.modes(count)[0]

    def eigenvalues(self, count: int) -> np.ndarray:
        """Damped first-order eigenvalues with positive imaginary part, ascending (1/s)."""
        return self.system.damped_eigenvalues(count)

    def classify_mode(self, shape: np.ndarray, samples: int = 41) -> tuple[str, int]:
        """``("bending" | "torsion", order)`` of a mode shape.

        Bending modes are symmetric about mid-chord (the tip corners move together), torsion modes
        antisymmetric; the order is one plus the number of sign changes along the span of the
        mid-chord deflection (bending) or of the edge-to-edge difference, i.e. the twist (torsion).
        """
        W, L = self.problem.width, self.problem.length
        y = np.linspace(0.0, L * (1 - 1.0 / samples), samples)  # the root itself is a node of every mode
        left = self.evaluate(shape, np.zeros_like(y), y)
        right = self.evaluate(shape, np.full_like(y, W), y)
        sym, anti = 0.5 * (left + right), 0.5 * (left - right)
        kind, line = ("bending", sym) if np.linalg.norm(sym) >= np.linalg.norm(anti) else ("torsion", anti)
        big = line[np.abs(line) > 1e-3 * np.abs(line).max()]
        return kind, 1 + int(np.count_nonzero(np.diff(np.sign(big))))

    def static_deflection(self, voltages: np.ndarray, load: np.ndarray | None = None) -> np.ndarray:
        """Equilibrium ``K z = b u (+ f)`` for patch voltages ``u`` (V) and an optional load vector ``f``."""
        rhs = self.actuation @ np.asarray(voltages, dtype=float)
        if load is not None:
            rhs = rhs + load
        return self.system.static_solve(rhs)

    def sensor_outputs(self, z: np.ndarray) -> np.ndarray:
        """Patch strain outputs ``C z`` for a field ``(n,)`` or a history ``(nt, n)``."""
        return np.asarray(z) @ self.sensing.T

    # -- targets and norms ------------------------------------------------------------------------
    def target_function(self, shape: str, amplitude: float | None = None):
        """The Table 5.1 shape ``z_d(x, y)`` (amplitude from the problem file unless given)."""
        if shape not in SHAPES:
            raise InputError(f"shape = {shape!r}: expected one of {', '.join(SHAPES)}")
        a = self.problem.targets.amplitude(shape) if amplitude is None else float(amplitude)
        return target_function(shape, self.problem.width, self.problem.length, a)

    def target(self, shape: str, amplitude: float | None = None) -> np.ndarray:
        """Coefficients of the L2 projection (eq. 5.16) of a Table 5.1 shape; velocity target is zero."""
        return self.project(self.target_function(shape, amplitude))

    def project(self, g) -> np.ndarray:
        """L2 projection ``S^-1 ∫ g phi`` of a function ``g(x, y)`` onto the deflection space."""
        return project(self.space, g, self.gram)

    def m_norm(self, z: np.ndarray) -> float | np.ndarray:
        """``||z||_M = sqrt(z^T M z)`` with the mass matrix (rows of ``(nt, n)`` give a history)."""
        z = np.asarray(z, dtype=float)
        return np.sqrt(np.einsum("...i,...i->...", z, np.asarray((self.mass @ z.T).T)))

    def l2_norm(self, z: np.ndarray) -> float:
        """``||w||_L2 = sqrt(z^T S z)`` of the deflection field."""
        z = np.asarray(z, dtype=float)
        return float(np.sqrt(z @ (self.gram @ z)))

    # -- fields -----------------------------------------------------------------------------------
    def evaluate(self, z: np.ndarray, x, y, dx: int = 0, dy: int = 0) -> np.ndarray:
        """Deflection (or a derivative) at points; ``z`` may be ``(n,)`` or ``(n, k)``."""
        return self.space.evaluate(z, np.ravel(x), np.ravel(y), dx, dy)

    def field(self, z: np.ndarray):
        """A callable ``(x, y) -> w`` for the deflection with coefficients ``z``."""

        def w(x, y):
            x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
            return self.evaluate(z, x, y).reshape(np.broadcast(x, y).shape)

        return w

    def evaluate_grid(self, z: np.ndarray, nx: int = 31, ny: int = 121, dx: int = 0, dy: int = 0):
        """Field on a uniform grid including the edges: ``X, Y, values`` of shape ``(ny, nx)``."""
        return self.space.evaluate_grid(z, nx, ny, dx, dy)

    @cached_property
    def _tip_matrix(self) -> sp.csr_matrix:
        return self.space.basis_matrix(np.array([0.0, self.problem.width]), np.zeros(2))

    def tip_corners(self, z: np.ndarray) -> np.ndarray:
        """``[w(0, 0), w(W, 0)]`` (m) for a field ``(n,)``, or ``(nt, 2)`` for a history ``(nt, n)``."""
        return np.asarray(self._tip_matrix @ np.asarray(z).T).T

    def curvatures(self, z: np.ndarray, x, y) -> np.ndarray:
        """``[w_xx, w_yy, 2 w_xy]`` at points, shape ``(3, npts)``."""
        return np.stack(
            [self.evaluate(z, x, y, 2, 0), self.evaluate(z, x, y, 0, 2), 2.0 * self.evaluate(z, x, y, 1, 1)]
        )

    def surface_strains(self, z: np.ndarray, x, y) -> np.ndarray:
        """``[eps_xx, eps_yy, gamma_xy]`` on the top face of the substrate, ``-(h/2) kappa`` (eq. 4.4).

        Uses the local substrate thickness ``h`` (skin or batten) at each point.
        """
        x, y = np.ravel(x), np.ravel(y)
        return -0.5 * self.thickness_at(x, y) * self.curvatures(z, x, y)

    def thickness_at(self, x, y) -> np.ndarray:
        """Substrate thickness (skin or batten, without patches) at points, m."""
        x, y = np.ravel(np.asarray(x, dtype=float)), np.ravel(np.asarray(y, dtype=float))
        h = np.full(x.shape, self.problem.skin.thickness)
        for b in self.problem.battens:
            x0, x1, y0, y1 = b.rect
            inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
            h[inside] = self.problem.batten.thickness
        return h
