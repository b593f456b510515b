"""L2 projection onto a spline space (eq. 5.16): ``c = S^-1 ∫ g phi``, ``S = ∫ phi phi^T``."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from wingopt.fe.forms import LinearForm, assemble_vector
from wingopt.fe.space import TensorSpace

__all__ = ["load_vector", "project"]


def load_vector(
    space: TensorSpace,
    g: Callable[[np.ndarray, np.ndarray], np.ndarray],
    breaks_x: Sequence[float] = (),
    breaks_y: Sequence[float] = (),
    order: int = 8,
) -> np.ndarray:
    """``∫ g phi`` with quadrature split at the given lines (where ``g`` jumps)."""
    form = LinearForm(lambda v, w: g(w.x, w.y) * v.value)
    return assemble_vector(space, form, space.cells(None, breaks_x, breaks_y), order=order)


def project(
    space: TensorSpace,
    g: Callable[[np.ndarray, np.ndarray], np.ndarray],
    gram: sp.spmatrix,
    breaks_x: Sequence[float] = (),
    breaks_y: Sequence[float] = (),
    order: int = 8,
) -> np.ndarray:
    """Coefficients of the L2 projection of ``g(x, y)`` onto ``space`` (``gram`` = its mass matrix)."""
    rhs = load_vector(space, g, breaks_x, breaks_y, order)
    return spla.spsolve(sp.csc_matrix(gram), rhs)
