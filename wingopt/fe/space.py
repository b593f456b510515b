"""Tensor-product spline spaces on rectangles, integration cells and field evaluation.

A 2-D basis function is ``phi_k(x, y) = Bx_m(x) By_n(y)`` with ``k = m * ny + n``: the y
index runs fastest, so a separable operator is ``kron(A_x, A_y)``.

Integration is organised in *cells*: axis-aligned rectangles that lie inside one element.
Cells cover either the whole domain or a region (a sensor, a patch), split at element edges
and at the region's own edges, so that the integrand is a polynomial on every cell and
Gauss quadrature on the cell is exact.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from wingopt.errors import InputError
from wingopt.fe.bspline import SplineBasis1D, gauss_legendre

__all__ = ["TensorSpace", "Cells", "Rect"]

Rect = tuple[float, float, float, float]
"""A rectangle ``(x0, x1, y0, y1)`` in metres."""


@dataclass(frozen=True)
class Cells:
    """Integration cells: rectangles ``[x0, x1] x [y0, y1]`` inside element ``(ex, ey)``."""

    ex: np.ndarray
    ey: np.ndarray
    x0: np.ndarray
    x1: np.ndarray
    y0: np.ndarray
    y1: np.ndarray

    def __len__(self) -> int:
        return int(self.ex.size)

    @property
    def area(self) -> np.ndarray:
        return (self.x1 - self.x0) * (self.y1 - self.y0)

    def subset(self, index: np.ndarray | slice) -> Cells:
        return Cells(*(getattr(self, f)[index] for f in ("ex", "ey", "x0", "x1", "y0", "y1")))

    def quadrature(self, order: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Tensor Gauss points ``x, y`` and weights ``w``, each of shape ``(ncell, order**2)``."""
        t, wt = gauss_legendre(order)
        tx = np.repeat(t, order)
        ty = np.tile(t, order)
        w = np.outer(wt, wt).ravel()
        x = self.x0[:, None] + (self.x1 - self.x0)[:, None] * tx[None, :]
        y = self.y0[:, None] + (self.y1 - self.y0)[:, None] * ty[None, :]
        return x, y, self.area[:, None] * w[None, :]


def _intervals(basis: SplineBasis1D, a: float, b: float, breaks: Sequence[float]) -> tuple:
    """Split ``[a, b]`` at element edges and at ``breaks``; element index of each piece."""
    pts = np.concatenate([[a, b], basis.nodes, np.asarray(breaks, dtype=float)])
    pts = np.unique(pts[(pts >= a) & (pts <= b)])
    # Merge points closer than round-off so no zero-width cells appear.
    keep = np.concatenate([[True], np.diff(pts) > 1e-12 * basis.length])
    pts = pts[keep]
    lo, hi = pts[:-1], pts[1:]
    e, _ = basis.locate(0.5 * (lo + hi))
    return e, lo, hi


BASIS_CACHE_SIZE = 4
"""Point sets whose basis matrices a :class:`TensorSpace` keeps (the most recent ones)."""

BASIS_CACHE_MIN_POINTS = 4096
"""Smaller point sets are evaluated afresh (cheap; not worth the memory)."""


def _digest(a: np.ndarray) -> bytes:
    import hashlib

    digest = hashlib.blake2b(np.ascontiguousarray(a).view(np.uint8), digest_size=16).digest()
    return digest + str(a.size).encode()


@dataclass(frozen=True)
class TensorSpace:
    """Tensor product of two :class:`SplineBasis1D` on ``[0, bx.length] x [0, by.length]``."""

    bx: SplineBasis1D
    by: SplineBasis1D

    @property
    def width(self) -> float:
        return self.bx.length

    @property
    def height(self) -> float:
        return self.by.length

    @property
    def shape(self) -> tuple[int, int]:
        """Number of basis functions per direction ``(nx, ny)``."""
        return self.bx.n, self.by.n

    @property
    def n(self) -> int:
        return self.bx.n * self.by.n

    @property
    def n_elements(self) -> tuple[int, int]:
        return self.bx.n_elements, self.by.n_elements

    @cached_property
    def transform(self) -> sp.csr_matrix:
        """Sparse map from modified to full (``(nx+..)*(ny+..)``) coefficients."""
        return sp.kron(self.bx.transform, self.by.transform, format="csr")

    @property
    def n_full(self) -> int:
        return self.bx.n_full * self.by.n_full

    # -- cells --------------------------------------------------------------------------
    def cells(
        self,
        rect: Rect | None = None,
        breaks_x: Sequence[float] = (),
        breaks_y: Sequence[float] = (),
    ) -> Cells:
        """Cells covering ``rect`` (default: the whole domain), split at the given lines."""
        if rect is None:
            rect = (0.0, self.width, 0.0, self.height)
        self.check_rect(rect)
        x0, x1, y0, y1 = rect
        ex, ax, bx = _intervals(self.bx, x0, x1, breaks_x)
        ey, ay, by = _intervals(self.by, y0, y1, breaks_y)
        nx, ny = ex.size, ey.size
        return Cells(
            ex=np.repeat(ex, ny),
            ey=np.tile(ey, nx),
            x0=np.repeat(ax, ny),
            x1=np.repeat(bx, ny),
            y0=np.tile(ay, nx),
            y1=np.tile(by, nx),
        )

    def check_rect(self, rect: Rect, name: str = "rect") -> None:
        """Raise :class:`InputError` unless ``rect`` is a non-empty rectangle in the domain."""
        try:
            x0, x1, y0, y1 = (float(v) for v in rect)
        except (TypeError, ValueError):
            raise InputError(f"{name} = {rect!r}: expected four numbers [x0, x1, y0, y1]") from None
        tol = 1e-12 * max(self.width, self.height)
        if not (x0 < x1 and y0 < y1):
            raise InputError(f"{name} = {list(rect)}: expected x0 < x1 and y0 < y1")
        if x0 < -tol or y0 < -tol or x1 > self.width + tol or y1 > self.height + tol:
            raise InputError(f"{name} = {list(rect)}: lies outside the domain [0, {self.width}] x [0, {self.height}]")

    # -- evaluation ---------------------------------------------------------------------
    def basis_matrix(self, x: np.ndarray, y: np.ndarray, dx: int = 0, dy: int = 0) -> sp.csr_matrix:
        """Sparse ``(npts, n)``: derivative ``(dx, dy)`` of every basis function at points.

        Large point sets (a quadrature of a fine mesh: error metrics, plots) are cached by their
        content, the last :data:`BASIS_CACHE_SIZE` per space: the same points evaluated again (the
        error of every sample of a history on one truth mesh) cost a hash, not a rebuild. The
        matrix returned is shared then: do not modify it in place.
        """
        x = np.atleast_1d(np.asarray(x, dtype=float)).ravel()
        y = np.atleast_1d(np.asarray(y, dtype=float)).ravel()
        if x.shape != y.shape:
            raise InputError(f"x and y must have the same number of points, got {x.size} and {y.size}")
        if x.size < BASIS_CACHE_MIN_POINTS:
            return (self._full_basis_matrix(x, y, dx, dy) @ self.transform).tocsr()
        key = (_digest(x), _digest(y), int(dx), int(dy))
        cache = self._basis_cache
        hit = cache.pop(key, None)
        if hit is None:
            hit = (self._full_basis_matrix(x, y, dx, dy) @ self.transform).tocsr()
            while len(cache) >= BASIS_CACHE_SIZE:
                cache.pop(next(iter(cache)))
        cache[key] = hit  # most recent last
        return hit

    @cached_property
    def _basis_cache(self) -> dict:
        return {}

    def __getstate__(self) -> dict:
        # The basis cache stays behind (a space sent to a worker process carries no matrices).
        return {k: v for k, v in self.__dict__.items() if k != "_basis_cache"}

    def local_basis(self, x: np.ndarray, y: np.ndarray, dx: int = 0, dy: int = 0):
        """The 16 non-zero full splines at each point: values ``(npts, 16)`` and full indices."""
        ex, tx = self.bx.locate(x)
        ey, ty = self.by.locate(y)
        vx = self.bx.local_values(ex, tx, dx)
        vy = self.by.local_values(ey, ty, dy)
        vals = (vx[:, :, None] * vy[:, None, :]).reshape(x.size, 16)
        return vals, self.local_dofs(ex, ey)

    def local_dofs(self, ex: np.ndarray, ey: np.ndarray) -> np.ndarray:
        """Full-basis indices ``(len(ex), 16)`` of the splines alive on elements ``(ex, ey)``."""
        ix = np.asarray(ex)[:, None] + np.arange(4)
        iy = np.asarray(ey)[:, None] + np.arange(4)
        return (ix[:, :, None] * self.by.n_full + iy[:, None, :]).reshape(-1, 16)

    def _full_basis_matrix(self, x, y, dx, dy) -> sp.csr_matrix:
        vals, cols = self.local_basis(x, y, dx, dy)
        rows = np.repeat(np.arange(x.size), 16)
        return sp.csr_matrix((vals.ravel(), (rows, cols.ravel())), shape=(x.size, self.n_full))

    def evaluate(self, coef: np.ndarray, x: np.ndarray, y: np.ndarray, dx: int = 0, dy: int = 0) -> np.ndarray:
        """Field ``Σ coef_k phi_k`` (or a derivative) at points; ``coef`` may be ``(n, m)``."""
        coef = np.asarray(coef)
        if coef.shape[0] != self.n:
            raise InputError(f"coefficients: length {coef.shape[0]}, expected {self.n} for this space")
        return self.basis_matrix(x, y, dx, dy) @ coef

    def evaluate_grid(self, coef: np.ndarray, nx: int = 57, ny: int = 29, dx: int = 0, dy: int = 0):
        """Field on a uniform grid including the edges: returns ``X, Y, values`` of shape ``(ny, nx)``."""
        xs = np.linspace(0.0, self.width, nx)
        ys = np.linspace(0.0, self.height, ny)
        X, Y = np.meshgrid(xs, ys)
        vals = self.evaluate(coef, X.ravel(), Y.ravel(), dx, dy)
        return X, Y, np.asarray(vals).reshape(ny, nx)
