"""Lowest undamped modes and static fields of a structural model: one solver policy, cached.

Every reduced model of the package (the QP's, the Kalman filter's, the closed-loop plant's, the
large Riccati solver's, the MHE's and the JEKF's) starts from the same two things: the lowest
undamped modes of the pencil ``(K, M)`` and the static fields ``K^-1 B``. They are computed here,
once per model, in one unit (circular frequency, rad/s), and :class:`ModeCache` keeps them so that
asking again (or for fewer modes) costs nothing.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from wingopt.errors import InputError

__all__ = ["lowest_modes", "ModeCache", "DENSE_LIMIT"]

DENSE_LIMIT = 200
"""Up to this many dofs, or when more than a quarter of all modes is asked for, the dense
generalized eigensolver is used; above it, shift-invert Lanczos around 0."""


def _dense(a) -> np.ndarray:
    return a.toarray() if sp.issparse(a) else np.asarray(a, dtype=float)


def lowest_modes(mass, stiffness, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Lowest ``count`` circular frequencies (rad/s) and M-orthonormal shapes of ``K phi = w^2 M phi``.

    Parameters
    ----------
    mass, stiffness : sparse matrix or ndarray, shape (n, n)
        Symmetric; ``mass`` positive definite, ``stiffness`` positive semi-definite.
    count : int
        Number of modes, ``1 <= count <= n``.

    Returns
    -------
    omega : ndarray (count,)
        Ascending circular frequencies, rad/s (negative round-off clipped to 0).
    shapes : ndarray (n, count)
        Mode shapes with ``shapes^T M shapes = I``.
    """
    n = mass.shape[0]
    count = int(count)
    if not 1 <= count <= n:
        raise InputError(f"count = {count}: expected 1..{n} modes for this model")
    # Dense eigh is O(n^3) (about 1 s at n ~ 1000, far more on a loaded machine); shift-invert
    # Lanczos needs one sparse factorization and is as accurate for a few lowest modes. For many
    # modes (hundreds, the closed-loop plant) one dense solution beats Lanczos.
    if n <= DENSE_LIMIT or count > n // 4:
        lam, Phi = sla.eigh(_dense(stiffness), _dense(mass), subset_by_index=(0, count - 1))
    else:
        # A fixed start vector: ARPACK's default is random, which made results differ in the
        # last digits from run to run.
        lam, Phi = spla.eigsh(
            sp.csc_matrix(stiffness), k=count, M=sp.csc_matrix(mass), sigma=0.0, which="LM", v0=np.ones(n)
        )
        order = np.argsort(lam)
        lam, Phi = lam[order], Phi[:, order]
    return np.sqrt(np.clip(lam, 0.0, None)), Phi


class ModeCache:
    """Modes and static fields of one ``(M, K, B)``, computed on first use and kept.

    Modes are kept per requested count: the lowest modes of a larger solve agree with a smaller
    solve only to round-off, and serving one from the other would make a result depend on what was
    asked before (a study's records must not depend on the order its tasks ran in).
    """

    def __init__(self, mass, stiffness, input_matrix) -> None:
        self._mass, self._stiffness, self._input = mass, stiffness, input_matrix
        self._modes: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._lu = None
        self._fields: np.ndarray | None = None

    def modes(self, count: int) -> tuple[np.ndarray, np.ndarray]:
        """Lowest ``count`` ``(omega [rad/s], shapes)``; see :func:`lowest_modes`."""
        count = int(count)
        if count not in self._modes:
            omega, shapes = lowest_modes(self._mass, self._stiffness, count)
            # Shared by every caller: a write through one of them would corrupt the others.
            omega.setflags(write=False)
            shapes.setflags(write=False)
            self._modes[count] = (omega, shapes)
        return self._modes[count]

    def static_solve(self, rhs: np.ndarray) -> np.ndarray:
        """``K^-1 rhs`` with one sparse LU of ``K`` kept for the model's lifetime."""
        if self._lu is None:
            self._lu = spla.splu(sp.csc_matrix(self._stiffness))
        return self._lu.solve(np.ascontiguousarray(np.asarray(rhs, dtype=float)))

    def static_fields(self) -> np.ndarray:
        """``K^-1 B``: the static response to a unit of each input, ``(n, m)``."""
        if self._fields is None:
            self._fields = self.static_solve(_dense(self._input))
            self._fields.setflags(write=False)
        return self._fields
