"""Joint transition of the JEKF's state ``[z, z', f]``: the plant's exact ZOH with the load held.

Dense in physical coordinates (:func:`joint_transition`) or one 3x3 block per mode (the membrane's
damping is Rayleigh), both from :mod:`wingopt.dynamics` (no second derivation of the ZOH here).
"""

from __future__ import annotations

import numpy as np

from wingopt.dynamics import zoh
from wingopt.membrane.model import MembraneModel

__all__ = ["joint_transition"]


def joint_transition(model: MembraneModel, dt: float) -> np.ndarray:
    """Joint transition ``F_hat = [[F, G], [0, I]]`` of the state ``[z, z', f]`` (eqs. 6.22–6.24).

    ``F, G`` are the plant's exact zero-order hold (:func:`wingopt.dynamics.zoh`: one augmented
    exponential ``expm([[A, B], [0, 0]] dt)``, the seed's eq. 6.24): the load is held over the
    step. Dense ``(3n, 3n)``; for the fast filter see :class:`JointEKF`.
    """
    return _joint(*zoh(*_first_order(model), dt))


def _first_order(model: MembraneModel) -> tuple[np.ndarray, np.ndarray]:
    ss = model.system.state_space()
    return ss.A, ss.B


def _joint(F: np.ndarray, G: np.ndarray) -> np.ndarray:
    """``[[F, G], [0, I]]``: the load is a random walk (identity transition)."""
    n2, m = G.shape
    out = np.eye(n2 + m)
    out[:n2, :n2] = F
    out[:n2, n2:] = G
    return out


def _modal_blocks(modal, dt: float) -> np.ndarray:
    """Per-mode joint transition ``[[F_k, g_k], [0, 1]]``, shape (r, 3, 3), from the modal ZOH.

    The same augmented exponential as :func:`joint_transition`, block-diagonalised by the modes
    (:meth:`wingopt.dynamics.ModalModel.discretize`).
    """
    disc = modal.discretize(dt)
    out = np.zeros((modal.count, 3, 3))
    out[:, :2, :2] = disc.F
    out[:, :2, 2] = disc.g
    out[:, 2, 2] = 1.0
    return out
