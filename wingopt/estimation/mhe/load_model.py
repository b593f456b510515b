"""Temporal model of the load in the moving-horizon estimator: the random walk's process noise.

``constant``: the load does not change; no process noise, the information about it accumulates
over the whole record (a change is left to the consistency test, :mod:`wingopt.estimation.mhe.consistency`).

``random_walk``: between two load blocks ``tau`` seconds apart the load changes by a Gaussian
increment, mostly in **amplitude** and much more slowly in **shape**::

    du ~ N(0, Q(tau)),   Q(tau) = |f^|^2 [ (tau / T_a) v v^T + (tau / T_s) G^-1 ],   v = u^ / |f^|

with ``G`` the L2 metric of the load (the load space's Gram matrix in modal-force coordinates),
``u^`` the start-up's load estimate and ``|f^|`` its L2 norm, ``T_a`` (``load_timescale``) the time
over which the load's amplitude may change by its own size (1 sigma) and ``T_s``
(``shape_timescale``) the same for a change of shape. The penalty between blocks is
``du^T Q(tau)^-1 du`` (Woodbury, below). The same increment is the process noise of the arrival
cost: when a window step drops a load block it is marginalised through this Gaussian, so old load
information is forgotten at the rate the model states.

Why this form (measured, ``docs/estimation.md``):

* A multiple of the Tikhonov weight (a first version: ``lambda T / tau`` in the roughness metric)
  is far too loose: ``lambda`` is chosen so that the roughness prior barely changes the misfit,
  i.e. it is far wider than the load in every direction the data resolve, and the estimate
  wandered by +-30 % between windows on a constant load. The increment must scale with the load.
* An isotropic walk (``T_s = T_a``) forgets the *shape*, which only the transient resolves: once
  the membrane is steady, 4 stretch sensors give 4 numbers per sample, and the load drifted along
  the directions they cannot see (on the protocol's constant L1 the lift went from 0.44 to -0.17
  N over 0.8 s). The amplitude is what steady data see (every stretch scales with its square) and
  what changes quickly in a tunnel (dynamic pressure, gusts); the shape (pressure distribution)
  changes with the angle of attack, slowly.

All in modal-force coordinates ``u`` of the estimator (``f = E u``, the smoothest load with those
modal forces, :class:`~wingopt.estimation.mhe.model.MHEModel`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.mhe.model import MHEModel

__all__ = ["RandomWalk", "l2_metric"]


def l2_metric(reduced: MHEModel) -> np.ndarray:
    """``E^T Gram E`` ``(m, m)``: the squared L2 norm of the load ``f = E u`` is ``u^T (E^T Gram E) u``."""
    E = reduced.load_map
    G = np.asarray(E.T @ (reduced.load_space.gram @ E))
    return 0.5 * (G + G.T)


@dataclass(frozen=True, eq=False)
class RandomWalk:
    """Process noise of the random-walk load model.

    Attributes
    ----------
    metric : ndarray ``(m, m)``
        ``G / |f^|^2``: the L2 metric relative to the size of the load.
    direction : ndarray ``(m,)``
        ``G u^ / |f^|^2``: the amplitude direction in the metric's dual (``direction @ u`` is the
        amplitude of ``u`` relative to the reference load).
    timescale, shape_timescale : float
        ``T_a`` and ``T_s`` (s).
    size : float
        ``|f^|``, L2 norm of the reference load.
    """

    metric: np.ndarray
    direction: np.ndarray
    timescale: float
    shape_timescale: float
    size: float

    @classmethod
    def build(
        cls,
        reduced: MHEModel,
        timescale: float,
        shape_timescale: float,
        u_ref: np.ndarray,
        metric: np.ndarray | None = None,
    ) -> RandomWalk:
        """Random walk relative to the reference load ``E u_ref`` (its size and direction)."""
        G = l2_metric(reduced) if metric is None else metric
        size2 = float(u_ref @ G @ u_ref)
        if not (np.isfinite(size2) and size2 > 0):
            raise InputError(
                f"load_model = 'random_walk': the start-up's load estimate has no size ({size2!r}), so the "
                "random walk has nothing to scale to; is there a load in the data? (try load_model='constant')"
            )
        return cls(G / size2, (G @ u_ref) / size2, float(timescale), float(shape_timescale), float(np.sqrt(size2)))

    def precision(self, tau: float) -> np.ndarray:
        """``Q(tau)^-1`` ``(m, m)``: information of the increment over ``tau`` seconds.

        With ``a = tau / T_a``, ``b = tau / T_s`` (relative variances) and ``v^T G v = |f^|^2``,
        Woodbury gives ``Q^-1 = (1 / b) [G - a / (a + b) G v v^T G] / |f^|^2``.
        """
        a = float(tau) / self.timescale
        b = float(tau) / self.shape_timescale
        d = self.direction
        P = (self.metric - (a / (a + b)) * np.outer(d, d)) / b
        return 0.5 * (P + P.T)
