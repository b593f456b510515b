"""Weak forms and their assembly.

A bilinear form is a small callback ``form(u, v, w)`` that returns the integrand for every
pair of local basis functions at every quadrature point, written like the equation::

    @BilinearForm
    def tension(u, v, w):
        return w.Tx * u.dx * v.dx + w.Ty * u.dy * v.dy

``u`` and ``v`` expose the local basis (``value, dx, dy, dxx, dyy, dxy`` or ``d(ax, ay)``)
shaped so that products broadcast to ``(cell, i, j, point)``; ``w`` holds the point
coordinates ``w.x, w.y`` and any per-cell data passed to :func:`assemble` (arrays of leading
length ``ncell``, e.g. piecewise-constant materials).

One assembly loop (:func:`assemble`) integrates any form cell by cell. Forms built with
:func:`separable` from constant-coefficient terms also carry their Kronecker structure, and
:func:`assemble` then takes the fast path ``Σ c kron(G_x, G_y)`` of 1-D Gram matrices when
the integral is over the whole domain; both paths agree to round-off (tested).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from wingopt.fe.space import Cells, TensorSpace

__all__ = [
    "Derivative",
    "BilinearForm",
    "LinearForm",
    "separable",
    "assemble",
    "assemble_mixed",
    "assemble_vector",
    "integrate",
    "VALUE",
    "DX",
    "DY",
    "DXX",
    "DYY",
    "DXY",
]


@dataclass(frozen=True)
class Derivative:
    """Partial derivative order ``(ax, ay)``."""

    ax: int
    ay: int


VALUE, DX, DY = Derivative(0, 0), Derivative(1, 0), Derivative(0, 1)
DXX, DYY, DXY = Derivative(2, 0), Derivative(0, 2), Derivative(1, 1)


class _LocalBasis:
    """The 16 local splines of each cell at its quadrature points, derivatives on demand."""

    def __init__(self, space: TensorSpace, cells: Cells, x: np.ndarray, y: np.ndarray, shape: tuple):
        self._space, self._cells, self._shape = space, cells, shape
        hx, hy = space.bx.h, space.by.h
        self._tx = x / hx - cells.ex[:, None]
        self._ty = y / hy - cells.ey[:, None]
        self._cache: dict[tuple[int, int], np.ndarray] = {}

    def d(self, ax: int, ay: int) -> np.ndarray:
        key = (ax, ay)
        if key not in self._cache:
            vx = self._space.bx.local_values(None, self._tx, ax)  # (c, q, 4)
            vy = self._space.by.local_values(None, self._ty, ay)
            vals = np.einsum("cqa,cqb->cabq", vx, vy).reshape(self._tx.shape[0], 16, -1)
            self._cache[key] = vals.reshape(self._shape)
        return self._cache[key]

    value = property(lambda s: s.d(0, 0))
    dx = property(lambda s: s.d(1, 0))
    dy = property(lambda s: s.d(0, 1))
    dxx = property(lambda s: s.d(2, 0))
    dyy = property(lambda s: s.d(0, 2))
    dxy = property(lambda s: s.d(1, 1))


class _Data:
    """Point coordinates and per-cell data, reshaped to broadcast against the local basis."""

    def __init__(self, x: np.ndarray, y: np.ndarray, data: Mapping[str, Any], lead: int, index):
        shape = (x.shape[0],) + (1,) * lead + (x.shape[1],)
        self.x = x.reshape(shape)
        self.y = y.reshape(shape)
        for name, val in data.items():
            arr = np.asarray(val)
            if arr.ndim >= 1 and index is not None:
                arr = arr[index]
                arr = arr.reshape((arr.shape[0],) + (1,) * (lead + 1) + arr.shape[1:])
            setattr(self, name, arr)


class BilinearForm:
    """A bilinear weak form ``a(u, v)`` given by its integrand callback.

    Parameters
    ----------
    integrand : callable ``(u, v, w) -> array``
        Returns the integrand broadcastable to ``(cell, i, j, point)``.
    terms : sequence of ``(coef, Derivative, Derivative)``, optional
        The same form as a sum of constant-coefficient separable terms
        ``coef * ∫ d_u(phi_i) d_v(phi_j)``, which enables the Kronecker fast path.
    """

    def __init__(self, integrand: Callable, terms: tuple | None = None) -> None:
        self.integrand = integrand
        self.terms = terms
        self.__doc__ = integrand.__doc__

    def __call__(self, u, v, w):
        return self.integrand(u, v, w)


class LinearForm:
    """A linear weak form ``l(v)`` given by its integrand callback ``(v, w) -> array``."""

    def __init__(self, integrand: Callable) -> None:
        self.integrand = integrand
        self.__doc__ = integrand.__doc__

    def __call__(self, v, w):
        return self.integrand(v, w)


def separable(*terms: tuple[float, Derivative, Derivative]) -> BilinearForm:
    """A constant-coefficient form ``Σ c ∫ d_u(phi_i) d_v(phi_j)``, e.g. ``separable((T, DX, DX))``."""
    terms = tuple((float(c), du, dv) for c, du, dv in terms)

    def integrand(u, v, w):
        return sum(c * u.d(du.ax, du.ay) * v.d(dv.ax, dv.ay) for c, du, dv in terms)

    return BilinearForm(integrand, terms)


def _chunks(n: int, size: int):
    for start in range(0, n, size):
        yield slice(start, min(start + size, n))


def _kron_assemble(row: TensorSpace, col: TensorSpace, terms) -> sp.csr_matrix:
    out = sp.csr_matrix((row.n, col.n))
    for c, du, dv in terms:
        gx = row.bx.gram(du.ax, dv.ax, col.bx)
        gy = row.by.gram(du.ay, dv.ay, col.by)
        out = out + c * sp.kron(gx, gy, format="csr")
    return out.tocsr()


def assemble(
    space: TensorSpace,
    form: BilinearForm,
    cells: Cells | None = None,
    data: Mapping[str, Any] | None = None,
    order: int = 4,
    method: str = "auto",
    chunk: int = 512,
) -> sp.csr_matrix:
    """Assemble the sparse ``(n, n)`` matrix of a bilinear form.

    Parameters
    ----------
    space : TensorSpace
    form : BilinearForm
    cells : Cells, optional
        Where to integrate (default: the whole domain).
    data : mapping, optional
        Per-cell arrays (leading length ``len(cells)``) or scalars, available as ``w.<name>``.
    order : int
        Gauss points per direction and cell (4 integrates cubic x cubic exactly).
    method : {"auto", "kron", "cells"}
        ``"auto"`` uses the Kronecker path for separable forms over the whole domain.
    chunk : int
        Cells per batch, to bound memory.
    """
    return assemble_mixed(space, space, form, cells, data, order, method, chunk)


def _restrict(full: sp.csr_matrix, row_space: TensorSpace, col_space: TensorSpace) -> sp.csr_matrix:
    """``T_row^T full T_col``: from the full spline basis to the two modified bases."""
    return (row_space.transform.T @ full @ col_space.transform).tocsr()


def _assemble_full(space, form, cells, data, order, chunk) -> sp.csr_matrix:
    """Cell-by-cell assembly on the full (unmodified) spline basis of ``space``'s mesh."""
    cells = space.cells() if cells is None else cells
    data = dict(data or {})
    rows, cols, vals = [], [], []
    for sl in _chunks(len(cells), chunk):
        c = cells.subset(sl)
        x, y, wq = c.quadrature(order)
        idx = np.arange(len(cells))[sl]
        u = _LocalBasis(space, c, x, y, (len(c), 16, 1, -1))
        v = _LocalBasis(space, c, x, y, (len(c), 1, 16, -1))
        w = _Data(x, y, data, 2, idx)
        integrand = np.broadcast_to(form(u, v, w), (len(c), 16, 16, x.shape[1]))
        local = np.einsum("cijq,cq->cij", integrand, wq)
        dofs = space.local_dofs(c.ex, c.ey)
        rows.append(np.repeat(dofs, 16, axis=1).ravel())
        cols.append(np.tile(dofs, (1, 16)).ravel())
        vals.append(local.ravel())
    return sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(space.n_full, space.n_full),
    )


def _same_mesh(a: TensorSpace, b: TensorSpace) -> bool:
    return all(p.length == q.length and p.n_elements == q.n_elements for p, q in ((a.bx, b.bx), (a.by, b.by)))


def assemble_mixed(
    row_space: TensorSpace,
    col_space: TensorSpace,
    form: BilinearForm,
    cells: Cells | None = None,
    data: Mapping[str, Any] | None = None,
    order: int = 4,
    method: str = "auto",
    chunk: int = 512,
) -> sp.csr_matrix:
    """Assemble the ``(row_space.n, col_space.n)`` matrix ``∫ form(phi_i, psi_j)`` of two spaces.

    Both spaces must live on the same mesh: they are then the same full spline space with
    different edge modifications, so the matrix is ``T_row^T A_full T_col`` with ``A_full``
    assembled once on the full basis. Example: the coupling ``∫ phi_w psi_f`` between a
    zero-edge deflection space and a free-edge load space.

    Parameters are those of :func:`assemble`; ``u`` in the form runs over ``row_space`` and
    ``v`` over ``col_space``.
    """
    if method not in ("auto", "kron", "cells"):
        raise ValueError(f"method = {method!r}: expected 'auto', 'kron' or 'cells'")
    if not _same_mesh(row_space, col_space):
        raise ValueError("assemble_mixed: the two spaces must have the same extent and elements")
    whole = cells is None and not data
    if method == "kron" or (method == "auto" and whole and form.terms is not None):
        if form.terms is None or not whole:
            raise ValueError("the Kronecker path needs a separable form over the whole domain")
        return _kron_assemble(row_space, col_space, form.terms)
    return _restrict(_assemble_full(row_space, form, cells, data, order, chunk), row_space, col_space)


def assemble_vector(
    space: TensorSpace,
    form: LinearForm,
    cells: Cells | None = None,
    data: Mapping[str, Any] | None = None,
    order: int = 6,
    chunk: int = 1024,
) -> np.ndarray:
    """Assemble the ``(n,)`` vector of a linear form, e.g. a load ``∫ P phi``."""
    cells = space.cells() if cells is None else cells
    data = dict(data or {})
    out = np.zeros(space.n_full)
    for sl in _chunks(len(cells), chunk):
        c = cells.subset(sl)
        x, y, wq = c.quadrature(order)
        v = _LocalBasis(space, c, x, y, (len(c), 16, -1))
        w = _Data(x, y, data, 1, np.arange(len(cells))[sl])
        integrand = np.broadcast_to(form(v, w), (len(c), 16, x.shape[1]))
        np.add.at(out, space.local_dofs(c.ex, c.ey).ravel(), np.einsum("ciq,cq->ci", integrand, wq).ravel())
    return space.transform.T @ out


def integrate(space: TensorSpace, integrand: Callable, cells: Cells | None = None, order: int = 6) -> float:
    """``∫ integrand(x, y)`` over cells (default: the domain) by cell-wise Gauss quadrature."""
    cells = space.cells() if cells is None else cells
    x, y, wq = cells.quadrature(order)
    return float(np.sum(np.asarray(integrand(x, y)) * wq))
