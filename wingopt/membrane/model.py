"""The membrane-wing FE model (chapter 6, spec §2).

``rho h M z'' + D z' + K_T z = p`` with ``D = gamma M + eta K_T`` and ``p = M f`` for a load
``P ≈ Σ f_i phi_i`` in the deflection basis. Zero deflection on all four edges.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from wingopt.dynamics import ModalModel, SecondOrderSystem
from wingopt.fe import (
    DX,
    DXX,
    DY,
    DYY,
    VALUE,
    EdgeCondition,
    SplineBasis1D,
    TensorSpace,
    assemble,
    integrate,
    load_vector,
    project,
    separable,
)
from wingopt.membrane.loads import PressureLoad
from wingopt.membrane.sensors import StretchSensors
from wingopt.problem.membrane import MembraneProblem

__all__ = ["MembraneModel", "membrane_space"]

log = logging.getLogger(__name__)


def membrane_space(width: float, height: float, nodes: tuple[int, int], edge=EdgeCondition.ZERO) -> TensorSpace:
    """Cubic-spline space with ``nodes`` in x and y and the same edge condition on all edges."""
    nx, ny = nodes
    return TensorSpace(SplineBasis1D(width, nx - 1, edge, edge), SplineBasis1D(height, ny - 1, edge, edge))


@dataclass(frozen=True, eq=False)
class MembraneModel:
    """Assembled operators of a membrane problem on one mesh.

    Attributes
    ----------
    problem : MembraneProblem
    space : TensorSpace
    gram : sparse, ``M = ∫ phi phi^T``
    stiffness : sparse, ``K_T = ∫ (Tx phi_x phi_x^T + Ty phi_y phi_y^T)``
    regularizer : sparse, ``Lam = ∫ (phi_xx phi_xx^T + phi_yy phi_yy^T)`` (eq. 6.45)
    sensors : StretchSensors
    """

    problem: MembraneProblem
    space: TensorSpace
    gram: sp.csr_matrix
    stiffness: sp.csr_matrix
    regularizer: sp.csr_matrix
    sensors: StretchSensors
    build_seconds: float = 0.0

    @classmethod
    def from_problem(cls, problem: MembraneProblem, nodes: tuple[int, int] | None = None) -> MembraneModel:
        """Assemble the model of ``problem`` (on ``nodes`` instead of the problem's mesh if given).

        A problem of another kind, a malformed mesh and a mesh that cannot fit in memory
        (:func:`wingopt.resources.estimate_modes`) raise an :class:`~wingopt.errors.InputError`.
        """
        from wingopt import resources
        from wingopt.problem import as_problem

        t0 = time.perf_counter()
        problem = as_problem(problem, "membrane")
        if nodes is not None:
            problem = problem.with_mesh(nodes)
        resources.check(resources.estimate_modes(problem.nodes, "membrane", knob="mesh"))
        space = membrane_space(problem.width, problem.height, problem.nodes)
        T = problem.material.tension
        gram = assemble(space, separable((1.0, VALUE, VALUE)))
        stiffness = assemble(space, separable((T, DX, DX), (T, DY, DY)))
        regularizer = assemble(space, separable((1.0, DXX, DXX), (1.0, DYY, DYY)))
        sensors = StretchSensors.assemble(space, problem.sensors)
        elapsed = time.perf_counter() - t0
        log.debug("membrane model %dx%d: %d dofs in %.3f s", *problem.nodes, space.n, elapsed)
        return cls(problem, space, gram, stiffness, regularizer, sensors, elapsed)

    @property
    def n(self) -> int:
        return self.space.n

    def __repr__(self) -> str:
        # The dataclass repr prints the problem and every sparse operator (2000+ characters).
        nx, ny = self.problem.nodes
        return (
            f"MembraneModel(problem={self.problem.name!r}, mesh {nx}x{ny}, dofs={self.n}, "
            f"sensors={len(self.problem.sensors)}, tension={self.problem.material.tension:.4g} N/m, "
            f"built in {self.build_seconds:.3g} s)"
        )

    @property
    def mass(self) -> sp.csr_matrix:
        """``rho h M``."""
        return self.problem.material.areal_density * self.gram

    @property
    def damping(self) -> sp.csr_matrix:
        """``D = gamma M + eta K_T`` (un-scaled Gram, as in the seed: reproduces Table 6.3)."""
        mat = self.problem.material
        return (mat.viscous * self.gram + mat.kelvin_voigt * self.stiffness).tocsr()

    @cached_property
    def system(self) -> SecondOrderSystem:
        """``rho h M z'' + D z' + K_T z = M f``: the input is the load coefficient vector ``f``."""
        return SecondOrderSystem(self.mass, self.damping, self.stiffness, self.gram)

    def modal(self, count: int | None = None) -> ModalModel:
        """Exact modal decoupling (the damping is Rayleigh), lowest ``count`` modes (default all)."""
        return ModalModel.from_system(self.system, count)

    def frequencies_hz(self, count: int) -> np.ndarray:
        """Lowest undamped natural frequencies, Hz."""
        omega, _ = self.system.undamped_modes(count)
        return omega / (2 * np.pi)

    def eigenvalues(self, count: int) -> np.ndarray:
        """Damped first-order eigenvalues with positive imaginary part, ascending."""
        return self.system.damped_eigenvalues(count)

    # -- fields -------------------------------------------------------------------------
    def project(self, g, breaks_x=(), breaks_y=()) -> np.ndarray:
        """L2 projection of ``g(x, y)`` onto the deflection space (a :class:`PressureLoad` too)."""
        if isinstance(g, PressureLoad):
            breaks_x, breaks_y = g.breaks_x, g.breaks_y
        return project(self.space, g, self.gram, breaks_x, breaks_y)

    def static_deflection(self, load_coefficients: np.ndarray) -> np.ndarray:
        """Equilibrium ``K_T z = M f``."""
        return self.system.static_solve(self.gram @ load_coefficients)

    def l2_norm(self, coef: np.ndarray) -> float:
        """``||Σ c_i phi_i||_L2 = sqrt(c^T M c)``."""
        return float(np.sqrt(coef @ (self.gram @ coef)))

    def relative_l2_error(self, estimate: np.ndarray, truth) -> float:
        """``||truth - estimate||_L2 / ||truth||_L2``; ``truth`` is a callable ``(x, y)`` or coefficients."""
        if callable(truth):
            num = integrate(self.space, lambda x, y: (truth(x, y) - self._eval(estimate, x, y)) ** 2, order=8)
            den = integrate(self.space, lambda x, y: truth(x, y) ** 2, order=8)
            return float(np.sqrt(num / den))
        diff = np.asarray(truth) - estimate
        return self.l2_norm(diff) / self.l2_norm(np.asarray(truth))

    def _eval(self, coef, x, y):
        return self.space.evaluate(coef, x.ravel(), y.ravel()).reshape(x.shape)

    def field(self, coef: np.ndarray):
        """A callable ``(x, y) -> values`` for the field with coefficients ``coef``."""
        return lambda x, y: self._eval(coef, np.asarray(x, dtype=float), np.asarray(y, dtype=float))

    @cached_property
    def basis_integrals(self) -> np.ndarray:
        """``∫ phi_i`` for every basis function: the lift of a load is ``basis_integrals @ f``."""
        return load_vector(self.space, lambda x, y: np.ones_like(x), order=4)

    def lift(self, load_coefficients: np.ndarray) -> np.ndarray:
        """Resultant ``∫ P`` (N) of a load in the deflection basis; ``(nt, n)`` gives a history."""
        return np.asarray(load_coefficients) @ self.basis_integrals
