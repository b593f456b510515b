"""The tangent of the force over a record, in the form the compiled tangent loop takes.

The record tangent (:meth:`~wingopt.membrane.modal.base.ModalMembrane.simulate_tangent`) needs the
force's derivative over every interval; a record fit's load is shapes times an amplitude history
(and gust knots), so the derivative is one base matrix scaled per interval plus a few columns:
:class:`ForceTangent` holds exactly that, and the compiled loop builds each interval's from it.
:func:`settled_from` says from which interval on the force and its tangent no longer change (the
loop then stops once the state has settled).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ForceTangent", "settled_from"]


@dataclass(frozen=True, eq=False)
class ForceTangent:
    """Tangent of the force held over interval ``k``: ``amp[k] * base`` plus, on the rows ``g0 + g``
    of the gust knots, ``hats[k, g] * fc`` (``(P, m)``; ``hats`` may have no columns)."""

    amp: np.ndarray
    base: np.ndarray
    hats: np.ndarray
    g0: int
    fc: np.ndarray

    def __call__(self, k: int) -> np.ndarray:
        du = self.amp[k] * self.base
        ng = self.hats.shape[1]
        du[self.g0 : self.g0 + ng] += self.hats[k][:, None] * self.fc[None]
        return du


def settled_from(forces: np.ndarray, amp: np.ndarray | None = None, hats: np.ndarray | None = None) -> int:
    """First interval from which the force (and its tangent) no longer changes (``N``: never)."""
    N = forces.shape[0]
    moving = np.any(forces[1:] != forces[:-1], axis=1)
    if amp is not None:
        moving |= amp[1:N] != amp[: N - 1]
        if hats.shape[1]:
            moving |= np.any(hats[1:N] != hats[: N - 1], axis=1)
    idx = np.flatnonzero(moving)
    return 0 if idx.size == 0 else int(idx[-1]) + 1
