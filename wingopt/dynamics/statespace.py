"""Second-order structural systems, first-order state space, and exact zero-order hold.

``M z'' + D z' + K z = B u`` becomes ``x' = A x + B_x u`` with ``x = [z; z']``::

    A = [[0, I], [-M^-1 K, -M^-1 D]],   B_x = [[0], [M^-1 B]]

and the zero-order-hold discretisation ``x_{k+1} = F x_k + G u_k`` is taken from one
augmented exponential ``expm([[A, B], [0, 0]] dt) = [[F, G], [0, I]]`` (never by inverting A).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from wingopt.dynamics.modes import ModeCache
from wingopt.errors import InputError

__all__ = ["StateSpace", "SecondOrderSystem", "zoh", "discretize", "simulate"]


def _dense(a) -> np.ndarray:
    return a.toarray() if sp.issparse(a) else np.asarray(a, dtype=float)


@dataclass(frozen=True, eq=False)
class StateSpace:
    """Linear system ``x' = A x + B u, y = C x + D u`` (``dt is None``) or its discrete twin.

    Parameters
    ----------
    A, B : ndarray
        Dynamics and input matrices.
    C, D : ndarray, optional
        Output matrices (default: full state out, no feedthrough).
    dt : float, optional
        Sample period; ``None`` for a continuous-time system.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray | None = None
    D: np.ndarray | None = None
    dt: float | None = None
    state_names: tuple[str, ...] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        n = self.A.shape[0]
        if self.A.shape != (n, n):
            raise InputError(f"A: shape {self.A.shape}, expected a square matrix")
        if self.B.ndim != 2 or self.B.shape[0] != n:
            raise InputError(f"B: shape {self.B.shape}, expected ({n}, m)")
        if self.C is None:
            object.__setattr__(self, "C", np.eye(n))
        if self.D is None:
            object.__setattr__(self, "D", np.zeros((self.C.shape[0], self.B.shape[1])))

    @property
    def nstates(self) -> int:
        return self.A.shape[0]

    @property
    def ninputs(self) -> int:
        return self.B.shape[1]

    @property
    def noutputs(self) -> int:
        return self.C.shape[0]

    @property
    def isdiscrete(self) -> bool:
        return self.dt is not None

    def poles(self) -> np.ndarray:
        return np.linalg.eigvals(self.A)

    def __repr__(self) -> str:
        # Sizes and sampling, as python-control's summary line; the matrices stay attributes
        # (a plate's A is 1000s of numbers).
        kind = "continuous" if self.dt is None else f"discrete, dt={self.dt:g} s"
        return f"StateSpace(states={self.nstates}, inputs={self.ninputs}, outputs={self.noutputs}, {kind})"

    def to_control(self):
        """This system as a ``python-control`` ``StateSpace`` (needs the ``control`` package)."""
        try:
            import control
        except ImportError as exc:  # pragma: no cover - optional dependency
            raise ImportError("to_control() needs python-control: pip install control") from exc
        return control.ss(self.A, self.B, self.C, self.D, 0 if self.dt is None else self.dt)


def zoh(A: np.ndarray, B: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order hold ``F = e^{A dt}``, ``G = ∫_0^dt e^{A s} ds B`` from one exponential."""
    if not (np.isfinite(dt) and dt > 0):
        raise InputError(f"dt = {dt!r}: expected a positive sample period (s)")
    A, B = _dense(A), _dense(B)
    n, m = B.shape
    aug = np.zeros((n + m, n + m))
    aug[:n, :n] = A
    aug[:n, n:] = B
    E = sla.expm(aug * dt)
    return E[:n, :n], E[:n, n:]


def discretize(sys: StateSpace, dt: float) -> StateSpace:
    """Zero-order-hold discretisation of a continuous :class:`StateSpace`."""
    if sys.isdiscrete:
        raise InputError("discretize: the system is already discrete")
    F, G = zoh(sys.A, sys.B, dt)
    return StateSpace(F, G, sys.C, sys.D, dt=dt, state_names=sys.state_names)


def simulate(sys: StateSpace, x0: np.ndarray, u: np.ndarray) -> np.ndarray:
    """States ``x_0..x_N`` of a discrete system driven by inputs ``u`` of shape ``(N, m)``."""
    if not sys.isdiscrete:
        raise InputError("simulate: discretize the system first (dt is None)")
    u = np.asarray(u, dtype=float)
    if u.ndim != 2 or u.shape[1] != sys.ninputs:
        raise InputError(f"u: shape {u.shape}, expected (steps, {sys.ninputs})")
    X = np.empty((u.shape[0] + 1, sys.nstates))
    X[0] = x0
    Gu = u @ sys.B.T
    for k in range(u.shape[0]):
        X[k + 1] = sys.A @ X[k] + Gu[k]
    return X


@dataclass(frozen=True, eq=False)
class SecondOrderSystem:
    """``M z'' + D z' + K z = B u`` with sparse or dense symmetric ``M`` (SPD), ``D``, ``K``.

    Parameters
    ----------
    mass, damping, stiffness : sparse or ndarray, shape (n, n)
    input_matrix : sparse or ndarray, shape (n, m)
    """

    mass: object
    damping: object
    stiffness: object
    input_matrix: object

    @property
    def n(self) -> int:
        return self.mass.shape[0]

    def state_space(self) -> StateSpace:
        """The first-order form with state ``[z; z']`` (dense)."""
        n = self.n
        M = _dense(self.mass)
        Minv_K = sla.solve(M, _dense(self.stiffness), assume_a="pos")
        Minv_D = sla.solve(M, _dense(self.damping), assume_a="pos")
        Minv_B = sla.solve(M, _dense(self.input_matrix), assume_a="pos")
        A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv_K, -Minv_D]])
        B = np.vstack([np.zeros_like(Minv_B), Minv_B])
        return StateSpace(A, B)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_cache", ModeCache(self.mass, self.stiffness, self.input_matrix))

    def undamped_modes(self, count: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Lowest ``count`` (default all) circular frequencies (rad/s) and M-orthonormal mode shapes.

        Computed once per system (:class:`~wingopt.dynamics.modes.ModeCache`) and kept.
        """
        return self._cache.modes(self.n if count is None else count)

    def static_solve(self, rhs: np.ndarray) -> np.ndarray:
        """``K^-1 rhs`` (one sparse LU of ``K``, kept)."""
        return self._cache.static_solve(rhs)

    def static_fields(self) -> np.ndarray:
        """``K^-1 B``: the static field of a unit of each input, ``(n, m)`` (computed once, read-only)."""
        return self._cache.static_fields()

    def modal_damping(self, Phi: np.ndarray) -> np.ndarray:
        """``Phi^T D Phi`` for M-orthonormal modes ``Phi``."""
        return Phi.T @ (self.damping @ Phi)

    def is_proportionally_damped(self, Phi: np.ndarray, rtol: float = 1e-9) -> bool:
        """Whether the modes also diagonalise ``D`` (Rayleigh damping)."""
        Dm = self.modal_damping(Phi)
        off = Dm - np.diag(np.diag(Dm))
        return bool(np.abs(off).max() <= rtol * max(np.abs(np.diag(Dm)).max(), 1e-300))

    def damped_eigenvalues(self, count: int) -> np.ndarray:
        """Eigenvalues of the first-order system with positive imaginary part, ascending by it.

        Proportionally damped systems decouple mode by mode (exact); otherwise the quadratic
        eigenproblem is solved by shift-invert on the sparse first-order pencil.
        """
        omega, Phi = self.undamped_modes(min(self.n, count + 8))
        if self.is_proportionally_damped(Phi):
            c = np.diag(self.modal_damping(Phi))
            s = -c / 2 + 1j * np.sqrt((omega**2 - c**2 / 4).astype(complex))
            s = s[s.imag > 0]
            return s[np.argsort(s.imag)][:count]
        return _quadratic_eigenvalues(self, count, sigma=0.9 * omega[0] * 1j)


def _quadratic_eigenvalues(sys: SecondOrderSystem, count: int, sigma: complex) -> np.ndarray:
    n = sys.n
    M, D, K = (sp.csc_matrix(a) for a in (sys.mass, sys.damping, sys.stiffness))
    I = sp.identity(n, format="csc")
    # Pencil  A x = s E x  with  A = [[0, I], [-K, -D]],  E = [[I, 0], [0, M]].
    A = sp.bmat([[None, I], [-K, -D]], format="csc")
    E = sp.bmat([[I, None], [None, M]], format="csc")
    k = min(2 * n - 2, 2 * count + 10)
    vals = spla.eigs(A.astype(complex), k=k, M=E.astype(complex), sigma=sigma, which="LM", return_eigenvectors=False)
    vals = vals[vals.imag > 1e-9 * np.abs(vals).max()]
    return vals[np.argsort(vals.imag)][:count]
