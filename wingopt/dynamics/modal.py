"""Modal coordinates for proportionally damped systems, with an exact per-mode zero-order hold.

With M-orthonormal modes ``Phi`` of ``(K, M)`` and Rayleigh damping ``D = a M + b K``, the
substitution ``z = Phi q`` decouples ``M z'' + D z' + K z = B u`` into scalar oscillators::

    q_k'' + c_k q_k' + omega_k^2 q_k = (Phi^T B)_k u

Each is discretised exactly by its own 3x3 augmented exponential (all modes in one batched
call), so keeping all modes is the exact ZOH of the full model at O(n) cost per step, and
keeping the lowest ones is modal truncation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from wingopt.dynamics.statespace import SecondOrderSystem
from wingopt.errors import InputError

__all__ = ["ModalModel", "DiscreteModalModel"]


@dataclass(frozen=True, eq=False)
class ModalModel:
    """Decoupled modal form: frequencies ``omega``, modal damping ``c``, shapes, modal input."""

    omega: np.ndarray
    damping: np.ndarray
    shapes: np.ndarray
    input_matrix: np.ndarray

    @classmethod
    def from_system(cls, sys: SecondOrderSystem, count: int | None = None, check: bool = True) -> ModalModel:
        """Modes of ``sys`` (lowest ``count``, default all); ``sys`` must be proportionally damped."""
        omega, Phi = sys.undamped_modes(count)
        if check and not sys.is_proportionally_damped(Phi):
            raise InputError("damping: not proportional to M and K, the modes do not decouple it")
        c = np.diag(sys.modal_damping(Phi))
        Bq = np.asarray(sp.csr_matrix(sys.input_matrix).T @ Phi).T
        return cls(omega=omega, damping=c, shapes=Phi, input_matrix=Bq)

    @property
    def count(self) -> int:
        return self.omega.size

    def discretize(self, dt: float) -> DiscreteModalModel:
        """Exact ZOH of every mode from a batched 3x3 augmented exponential."""
        if not (np.isfinite(dt) and dt > 0):
            raise InputError(f"dt = {dt!r}: expected a positive sample period (s)")
        n = self.count
        aug = np.zeros((n, 3, 3))
        aug[:, 0, 1] = 1.0
        aug[:, 1, 0] = -(self.omega**2)
        aug[:, 1, 1] = -self.damping
        aug[:, 1, 2] = 1.0
        E = sla.expm(aug * dt)
        return DiscreteModalModel(self, dt, E[:, :2, :2], E[:, :2, 2])

    def to_modal(self, z: np.ndarray, mass) -> np.ndarray:
        """Modal coordinates ``q = Phi^T M z`` of a field (or of each row of ``(nt, n)``)."""
        return np.asarray(mass @ np.asarray(z).T).T @ self.shapes


@dataclass(frozen=True, eq=False)
class DiscreteModalModel:
    """``[q, q']_{k+1} = F_k [q, q']_k + g_k (Phi^T B u)_k`` for every mode ``k``."""

    modal: ModalModel
    dt: float
    F: np.ndarray  # (n, 2, 2)
    g: np.ndarray  # (n, 2)

    def _advance(self, q, qd, drive):
        F, g = self.F, self.g
        return (
            F[:, 0, 0] * q + F[:, 0, 1] * qd + g[:, 0] * drive,
            F[:, 1, 0] * q + F[:, 1, 1] * qd + g[:, 1] * drive,
        )

    def step(self, q: np.ndarray, qd: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One step from modal displacement/velocity ``q, qd`` under input ``u`` held for ``dt``."""
        return self._advance(q, qd, self.modal.input_matrix @ u)

    def simulate(self, q0: np.ndarray, qd0: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Modal histories ``(N+1, n)`` under inputs ``u`` of shape ``(N, m)``."""
        u = np.asarray(u, dtype=float)
        m = self.modal.input_matrix.shape[1]
        if u.ndim != 2 or u.shape[1] != m:
            raise InputError(f"u: shape {u.shape}, expected (steps, {m})")
        drive = u @ self.modal.input_matrix.T
        Q = np.empty((u.shape[0] + 1, self.modal.count))
        Qd = np.empty_like(Q)
        Q[0], Qd[0] = q0, qd0
        for k in range(u.shape[0]):
            Q[k + 1], Qd[k + 1] = self._advance(Q[k], Qd[k], drive[k])
        return Q, Qd
