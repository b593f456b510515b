"""Uniform cubic B-spline bases on an interval, with per-edge boundary modifications.

An interval ``[0, length]`` is split into ``n_elements`` equal elements of size ``h``. The
``n_elements + 3`` cubic B-splines ``B_-1 .. B_{n+1}`` live on the extended uniform knot
vector; ``B_j`` is centred on node ``x_j = j h``. At an end, the three splines that do not
vanish there (``B_-1, B_0, B_1`` at the left) have values ``1/6, 2/3, 1/6`` and slopes
``-1/(2h), 0, 1/(2h)``, so the boundary conditions are linear combinations of them
(dissertation §4/§6, spec §1):

* ``ZERO`` (value zero):          ``{B_0 - 4 B_-1, B_1 - B_-1}``
* ``CLAMPED`` (value and slope):  ``{B_-1 - B_0/2 + B_1}``
* ``FREE``:                       ``{B_-1, B_0, B_1}`` unchanged

The modified basis is ``full_basis @ transform``; everything is evaluated on the full basis
(4 non-zero splines per element) and mapped by the sparse ``transform``.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from wingopt.errors import InputError

__all__ = ["EdgeCondition", "SplineBasis1D", "gauss_legendre"]


class EdgeCondition(enum.StrEnum):
    """Boundary modification at one end of a 1-D basis."""

    ZERO = "zero"
    CLAMPED = "clamped"
    FREE = "free"


# Combinations of the three end splines, listed from the outermost spline inwards
# (B_-1, B_0, B_1 at the left end; B_{n+1}, B_n, B_{n-1} at the right end).
_END_COMBINATIONS = {
    EdgeCondition.ZERO: np.array([[-4.0, 1.0, 0.0], [-1.0, 0.0, 1.0]]),
    EdgeCondition.CLAMPED: np.array([[1.0, -0.5, 1.0]]),
    EdgeCondition.FREE: np.eye(3),
}


def gauss_legendre(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre points and weights on ``[0, 1]``."""
    t, w = np.polynomial.legendre.leggauss(order)
    return 0.5 * (t + 1.0), 0.5 * w


def _segment_polynomials(t: np.ndarray, deriv: int) -> np.ndarray:
    """Derivative ``deriv`` (w.r.t. the local coordinate) of the four splines on one element.

    Returns shape ``t.shape + (4,)``; column ``a`` is ``B_{e-1+a}`` on element ``e``.
    """
    s = 1.0 - t
    if deriv == 0:
        cols = (s**3 / 6, (3 * t**3 - 6 * t**2 + 4) / 6, (-3 * t**3 + 3 * t**2 + 3 * t + 1) / 6, t**3 / 6)
    elif deriv == 1:
        cols = (-(s**2) / 2, 1.5 * t**2 - 2 * t, -1.5 * t**2 + t + 0.5, t**2 / 2)
    elif deriv == 2:
        cols = (s, 3 * t - 2, 1 - 3 * t, t)
    elif deriv == 3:
        one = np.ones_like(t)
        cols = (-one, 3 * one, -3 * one, one)
    else:
        return np.zeros(t.shape + (4,))
    return np.stack(cols, axis=-1)


@dataclass(frozen=True)
class SplineBasis1D:
    """Uniform cubic B-spline basis on ``[0, length]`` with boundary modifications.

    Parameters
    ----------
    length : float
        Extent of the interval (m).
    n_elements : int
        Number of uniform elements (at least 3, so the two ends' modifications are disjoint).
    left, right : EdgeCondition
        Boundary modification at ``x = 0`` and ``x = length``.
    """

    length: float
    n_elements: int
    left: EdgeCondition = EdgeCondition.ZERO
    right: EdgeCondition = EdgeCondition.ZERO

    def __post_init__(self) -> None:
        if not (isinstance(self.n_elements, (int, np.integer)) and self.n_elements >= 3):
            raise InputError(
                f"mesh: n_elements = {self.n_elements!r}: expected an integer >= 3 (at least 4 nodes per direction)"
            )
        if not (np.isfinite(self.length) and self.length > 0):
            raise InputError(f"length = {self.length!r}: expected a positive finite number (m)")
        object.__setattr__(self, "left", EdgeCondition(self.left))
        object.__setattr__(self, "right", EdgeCondition(self.right))

    @property
    def h(self) -> float:
        """Element size."""
        return self.length / self.n_elements

    @property
    def n_full(self) -> int:
        """Number of unmodified splines, ``n_elements + 3``."""
        return self.n_elements + 3

    @property
    def nodes(self) -> np.ndarray:
        """Element edges ``0, h, ..., length``."""
        return np.linspace(0.0, self.length, self.n_elements + 1)

    @cached_property
    def transform(self) -> sp.csr_matrix:
        """Sparse ``(n_full, n)`` map from modified to full coefficients."""
        n_full = self.n_full
        left = _END_COMBINATIONS[self.left]
        right = _END_COMBINATIONS[self.right]
        interior = n_full - 6
        T = np.zeros((n_full, left.shape[0] + interior + right.shape[0]))
        T[0:3, : left.shape[0]] = left.T
        T[3 : 3 + interior, left.shape[0] : left.shape[0] + interior] = np.eye(interior)
        # The right end's combinations are listed outermost first; flip both axes so that
        # columns stay in ascending spatial order.
        T[n_full - 3 :, left.shape[0] + interior :] = right.T[::-1, ::-1]
        return sp.csr_matrix(T)

    @property
    def n(self) -> int:
        """Number of modified basis functions."""
        return self.transform.shape[1]

    def locate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Element index and local coordinate in ``[0, 1]`` of each point."""
        x = np.asarray(x, dtype=float)
        tol = 1e-12 * self.length
        if np.any(x < -tol) or np.any(x > self.length + tol) or not np.all(np.isfinite(x)):
            bad = x[(x < -tol) | (x > self.length + tol) | ~np.isfinite(x)].ravel()[0]
            raise InputError(f"point {bad!r} lies outside [0, {self.length}]")
        u = np.clip(x, 0.0, self.length) / self.h
        e = np.clip(np.floor(u).astype(int), 0, self.n_elements - 1)
        return e, u - e

    def local_values(self, e: np.ndarray, t: np.ndarray, deriv: int = 0) -> np.ndarray:
        """Derivative ``deriv`` (w.r.t. x) of the four full splines of element ``e`` at ``t``."""
        del e  # uniform knots: the polynomials do not depend on the element
        return _segment_polynomials(np.asarray(t, dtype=float), deriv) / self.h**deriv

    def full_matrix(self, x: np.ndarray, deriv: int = 0) -> sp.csr_matrix:
        """Sparse ``(len(x), n_full)`` values of the unmodified splines (or a derivative)."""
        x = np.atleast_1d(np.asarray(x, dtype=float))
        e, t = self.locate(x)
        vals = self.local_values(e, t, deriv)
        rows = np.repeat(np.arange(x.size), 4)
        cols = (e[:, None] + np.arange(4)).ravel()
        return sp.csr_matrix((vals.ravel(), (rows, cols)), shape=(x.size, self.n_full))

    def matrix(self, x: np.ndarray, deriv: int = 0) -> sp.csr_matrix:
        """Sparse ``(len(x), n)`` values of the modified basis (or a derivative) at ``x``."""
        return (self.full_matrix(x, deriv) @ self.transform).tocsr()

    def gram(self, deriv_u: int = 0, deriv_v: int = 0, other: SplineBasis1D | None = None) -> sp.csr_matrix:
        """Exact ``∫ B^(deriv_u) C^(deriv_v)^T dx``, ``C`` = ``other``'s basis (default: this one).

        ``other`` must have the same interval and elements (only its edge conditions may differ).
        """
        other = self if other is None else other
        if (other.length, other.n_elements) != (self.length, self.n_elements):
            raise InputError("gram: the two bases must have the same interval and elements")
        tq, wq = gauss_legendre(4)  # exact up to degree 7 >= 3 + 3
        x = (np.arange(self.n_elements)[:, None] + tq[None, :]).ravel() * self.h
        w = np.tile(wq * self.h, self.n_elements)
        return (self.matrix(x, deriv_u).T @ sp.diags(w) @ other.matrix(x, deriv_v)).tocsr()
