"""Spaces in which the unknown pressure is represented (spec §4, "Load space").

* ``fixed``: the seed's choice, the deflection basis itself (zero on all edges), so the
  coupling ``∫ phi_w psi_f`` is the deflection Gram matrix ``M`` and ``p = M f`` (eq. 6.14).
  It cannot represent a pressure that is non-zero on an edge (load L3: its best L2
  approximation is already ~9 % off).
* ``free``: all ``n_el + 3`` cubic splines per direction (no edge modification), with its own
  Gram matrix, its own smoothness regulariser ``Lam_f = ∫ (psi_xx psi_xx^T + psi_yy psi_yy^T)``
  and the rectangular coupling ``G = ∫ phi_w psi_f^T`` to the deflection space, ``p = G f``.
  ``Lam_f`` alone does not penalise the bilinear functions ``1, x, y, xy``, and loads near an
  edge barely deflect a membrane that is fixed there, so with 4 sensors the edge values are
  unresolved: measured on L1–L3 the pure ``Lam_f`` estimate is 0.65–0.87 off. The free space
  therefore carries an edge term, ``Lam_f + beta k^4 L_y ∮ psi psi^T ds`` (``k^4 = (pi/W)^4 +
  (pi/L)^4``, the roughness of the smoothest interior shape; ``beta = edge_weight``, default 1): edge
  values are allowed but cost like roughness. See ``docs/estimation.md`` for the measurements.

Both live on the deflection mesh, so the coupling is assembled exactly with
:func:`wingopt.fe.assemble_mixed`.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from wingopt.errors import InputError
from wingopt.fe import (
    DXX,
    DYY,
    VALUE,
    EdgeCondition,
    TensorSpace,
    assemble,
    assemble_mixed,
    load_vector,
    project,
    separable,
)
from wingopt.membrane import MembraneModel, PressureLoad

__all__ = ["LoadSpaceKind", "LoadSpace", "build_load_space", "edge_mass"]


class LoadSpaceKind(enum.StrEnum):
    """Which basis represents the pressure."""

    FIXED = "fixed"
    FREE = "free"


@dataclass(frozen=True, eq=False)
class LoadSpace:
    """A pressure space on the deflection mesh with its operators.

    Attributes
    ----------
    kind : LoadSpaceKind
    space : TensorSpace
        The load basis ``psi``.
    gram : sparse ``(n_f, n_f)``
        ``∫ psi psi^T`` (for L2 norms and projections).
    coupling : sparse ``(n_w, n_f)``
        ``∫ phi_w psi_f^T``: the load vector of the deflection equation is ``coupling @ f``.
    regularizer : sparse ``(n_f, n_f)``
        ``Lam = ∫ (psi_xx psi_xx^T + psi_yy psi_yy^T)`` (eq. 6.45 in this basis).
    """

    kind: LoadSpaceKind
    space: TensorSpace
    gram: sp.csr_matrix
    coupling: sp.csr_matrix
    regularizer: sp.csr_matrix

    @property
    def n(self) -> int:
        return self.space.n

    @cached_property
    def basis_integrals(self) -> np.ndarray:
        """``∫ psi_i``: the lift of a load is ``basis_integrals @ f``."""
        return load_vector(self.space, lambda x, y: np.ones_like(x), order=4)

    def lift(self, coef: np.ndarray) -> np.ndarray:
        """Resultant ``∫ P`` (N) of coefficients ``(n_f,)`` or a history ``(nt, n_f)``."""
        return np.asarray(coef) @ self.basis_integrals

    def project(self, load) -> np.ndarray:
        """L2 projection of a pressure (a :class:`PressureLoad` or callable ``(x, y)``)."""
        bx, by = (load.breaks_x, load.breaks_y) if isinstance(load, PressureLoad) else ((), ())
        return project(self.space, load, self.gram, bx, by)

    def field(self, coef: np.ndarray):
        """Callable ``(x, y) -> pressure`` of coefficients ``coef``."""
        coef = np.asarray(coef, dtype=float)

        def pressure(x, y):
            x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
            return self.space.evaluate(coef, x.ravel(), y.ravel()).reshape(x.shape)

        return pressure

    def l2_norm(self, coef: np.ndarray) -> float:
        return float(np.sqrt(coef @ (self.gram @ coef)))


def edge_mass(space: TensorSpace) -> sp.csr_matrix:
    """``∮ psi psi^T ds`` over the four edges of the rectangle (exact)."""
    bx, by = space.bx, space.by
    ex = bx.matrix(np.array([0.0, bx.length]))
    ey = by.matrix(np.array([0.0, by.length]))
    return (sp.kron(ex.T @ ex, by.gram()) + sp.kron(bx.gram(), ey.T @ ey)).tocsr()


def build_load_space(
    model: MembraneModel, kind: str | LoadSpaceKind = LoadSpaceKind.FIXED, edge_weight: float = 1.0
) -> LoadSpace:
    """The load space ``kind`` (``"fixed"`` or ``"free"``) on ``model``'s mesh.

    ``edge_weight`` is ``beta`` of the free space's edge term (ignored for ``fixed``).
    """
    try:
        kind = LoadSpaceKind(kind)
    except ValueError:
        raise InputError(f"load space = {kind!r}: expected 'fixed' or 'free'") from None
    if kind is LoadSpaceKind.FIXED:
        return LoadSpace(kind, model.space, model.gram, model.gram, model.regularizer)
    wb = model.space
    free = EdgeCondition.FREE
    fspace = TensorSpace(
        type(wb.bx)(wb.bx.length, wb.bx.n_elements, free, free),
        type(wb.by)(wb.by.length, wb.by.n_elements, free, free),
    )
    gram = assemble(fspace, separable((1.0, VALUE, VALUE)))
    coupling = assemble_mixed(wb, fspace, separable((1.0, VALUE, VALUE)))
    reg = assemble(fspace, separable((1.0, DXX, DXX), (1.0, DYY, DYY)))
    if edge_weight:
        k4 = (np.pi / fspace.width) ** 4 + (np.pi / fspace.height) ** 4
        reg = (reg + edge_weight * k4 * fspace.height * edge_mass(fspace)).tocsr()
    return LoadSpace(kind, fspace, gram, coupling, reg)
