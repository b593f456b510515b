"""The parametric convex QP and the interface of its backends.

Every QP of the package has the same canonical form, with a parameter vector ``p`` (for the
morphing MPC: the estimated state and the previous input) entering the linear term and the
constraint bounds affinely::

    min_v  1/2 v^T H v + (q0 + Qp p)^T v + c(p)
    s.t.   A_eq v  = b0 + Bp p
           l0 + Lp p <= A_in v <= u0 + Up p

``H`` and both constraint matrices are constant, so a backend is *built once* and then re-solved
for each new ``p`` (:class:`QPBackend`). Every backend reports
:class:`~wingopt.optim.status.SolveStatus`, a failure raises :class:`~wingopt.errors.SolverError`
naming the backend and its own status, and the objective a backend reports is evaluated by
:meth:`ParametricQP.objective` on its solution, the same function for every backend.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from wingopt.errors import InputError
from wingopt.optim.status import SolveStatus, fail

__all__ = ["ParametricQP", "QPSolution", "QPBackend", "DenseForm"]


@dataclass(frozen=True, eq=False)
class ParametricQP:
    """``min 1/2 v'Hv + q(p)'v + c(p)`` s.t. ``A_eq v = b(p)``, ``l(p) <= A_in v <= u(p)``.

    All affine maps are stored as ``(constant, matrix)`` pairs: ``q(p) = q0 + Qp p`` and so on.
    ``c(p) = c0 + cp' p + 1/2 p' Cpp p`` is the constant part of the objective (it does not change
    the minimiser; it makes the reported objective the true cost).
    """

    H: sp.csc_matrix
    q0: np.ndarray
    Qp: sp.csc_matrix
    A_in: sp.csc_matrix
    l0: np.ndarray
    Lp: sp.csc_matrix
    u0: np.ndarray
    Up: sp.csc_matrix
    A_eq: sp.csc_matrix | None = None
    b0: np.ndarray | None = None
    Bp: sp.csc_matrix | None = None
    c0: float = 0.0
    cp: np.ndarray | None = None
    Cpp: np.ndarray | None = None
    names: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        nv = self.H.shape[0]
        if self.H.shape != (nv, nv) or self.A_in.shape[1] != nv:
            raise InputError(f"QP: H {self.H.shape} and A_in {self.A_in.shape} do not agree")
        if self.A_eq is not None and self.A_eq.shape[1] != nv:
            raise InputError(f"QP: A_eq {self.A_eq.shape} has the wrong number of columns (expected {nv})")

    @property
    def n_variables(self) -> int:
        return self.H.shape[0]

    @property
    def n_parameters(self) -> int:
        return self.Qp.shape[1]

    @property
    def n_eq(self) -> int:
        return 0 if self.A_eq is None else self.A_eq.shape[0]

    def q(self, p: np.ndarray) -> np.ndarray:
        return self.q0 + self.Qp @ p

    def lower(self, p: np.ndarray) -> np.ndarray:
        return self.l0 + self.Lp @ p

    def upper(self, p: np.ndarray) -> np.ndarray:
        return self.u0 + self.Up @ p

    def b(self, p: np.ndarray) -> np.ndarray:
        return self.b0 + self.Bp @ p

    def constant(self, p: np.ndarray) -> float:
        c = self.c0
        if self.cp is not None:
            c += float(self.cp @ p)
        if self.Cpp is not None:
            c += 0.5 * float(p @ (self.Cpp @ p))
        return c

    def objective(self, v: np.ndarray, p: np.ndarray) -> float:
        """The full cost at ``v`` (same evaluation for every backend)."""
        return float(0.5 * v @ (self.H @ v) + self.q(p) @ v + self.constant(p))

    def violation(self, v: np.ndarray, p: np.ndarray) -> float:
        """Largest constraint violation at ``v`` (in the QP's scaled units)."""
        Av = self.A_in @ v
        viol = max(float(np.max(self.lower(p) - Av, initial=0.0)), float(np.max(Av - self.upper(p), initial=0.0)))
        if self.A_eq is not None:
            viol = max(viol, float(np.max(np.abs(self.A_eq @ v - self.b(p)), initial=0.0)))
        return viol


class DenseForm:
    """Dense data of a :class:`ParametricQP` for the dense solvers, with per-``p`` updates.

    Splits ``A_in`` into *simple bounds* (its leading rows when they are the identity on the first
    variables, as in the condensed morphing QP: the voltage limits) and general rows, so that a
    solver with native box constraints (DAQP, ProxQP, PIQP) does not factor them as rows. The maps
    of the bounds are kept dense: ``p`` is small, and a dense GEMV is the cheapest update.
    """

    def __init__(self, qp: ParametricQP) -> None:
        n = qp.n_variables
        self.H = np.ascontiguousarray(qp.H.toarray())
        A = qp.A_in.tocsr()
        k = 0  # leading rows of A_in that are e_k^T, in order
        while k < min(A.shape[0], n):
            row = A.getrow(k)
            if row.nnz != 1 or row.indices[0] != k or row.data[0] != 1.0:
                break
            k += 1
        self.n_bounds = k
        self.A = np.ascontiguousarray(A[k:].toarray())
        self.Aeq = None if qp.A_eq is None else np.ascontiguousarray(qp.A_eq.toarray())
        self._q0, self._Qp = qp.q0, np.asarray(qp.Qp.toarray())
        self._l0, self._Lp = qp.l0, np.asarray(qp.Lp.toarray())
        self._u0, self._Up = qp.u0, np.asarray(qp.Up.toarray())
        if qp.A_eq is not None:
            self._b0, self._Bp = qp.b0, np.asarray(qp.Bp.toarray())

    def q(self, p: np.ndarray) -> np.ndarray:
        return self._q0 + self._Qp @ p

    def bounds(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """All rows of ``A_in`` (simple bounds first): ``(lower, upper)``."""
        return self._l0 + self._Lp @ p, self._u0 + self._Up @ p

    def b(self, p: np.ndarray) -> np.ndarray:
        return self._b0 + self._Bp @ p


@dataclass(frozen=True)
class QPSolution:
    """Result of one solve: minimiser ``v``, true objective, status, backend's own status, timing."""

    v: np.ndarray
    objective: float
    status: SolveStatus
    raw_status: str
    iterations: int
    backend: str
    seconds: float


class QPBackend:
    """Interface: built once for a :class:`ParametricQP`, then ``solve(p, warm=None)`` per step.

    Class attributes: ``name`` (the registry's name), ``formulation`` (the form of the morphing QP
    this solver is fastest on, measured: ``"sparse"`` or ``"condensed"``), ``default_tolerance``.
    """

    name = "base"
    formulation = "sparse"
    default_tolerance = 1e-8

    def __init__(self, qp: ParametricQP, tolerance: float | None = None, max_iterations: int = 10000) -> None:
        self.qp = qp
        self.tolerance = float(self.default_tolerance if tolerance is None else tolerance)
        self.max_iterations = int(max_iterations)
        t0 = time.perf_counter()
        self._build()
        self.build_seconds = time.perf_counter() - t0
        self.solves = 0

    def _build(self) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def _solve(self, p: np.ndarray, warm: np.ndarray | None) -> tuple[np.ndarray | None, str, SolveStatus, int]:
        raise NotImplementedError  # pragma: no cover - interface

    def solve(self, p: np.ndarray, warm: np.ndarray | None = None) -> QPSolution:
        """Minimiser for parameter ``p``; raises :class:`~wingopt.errors.SolverError` when the backend fails."""
        p = np.asarray(p, dtype=float)
        if p.shape != (self.qp.n_parameters,):
            raise InputError(f"p: shape {p.shape}, expected ({self.qp.n_parameters},)")
        t0 = time.perf_counter()
        v, raw, status, iters = self._solve(p, warm)
        seconds = time.perf_counter() - t0
        self.solves += 1
        if not status.ok or v is None or not np.all(np.isfinite(v)):
            raise fail(self.name, raw, "qp")
        return QPSolution(v, self.qp.objective(v, p), status, raw, iters, self.name, seconds)
