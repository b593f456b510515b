"""The plant of the closed-loop harness: the full plate model advanced by its exact zero-order hold.

Two exact-ZOH plants (see :func:`make_plant`):

* ``"dense"``: the first-order system ``x = [z; z']`` and one augmented matrix exponential
  (``expm`` of a ``2n + 9`` matrix). Exact; 0.2 s to build on 7x31, ~5 s on 13x61 (915 dofs).
* ``"modal"``: the lowest undamped modes up to ``band_hz`` plus one static-correction Ritz vector
  per patch (Dickens' modal truncation augmentation), with the *full* projected damping matrix
  (the plate's damping is not proportional), then the exact ZOH of that reduced system. The steady
  state under any voltage is the full model's exactly (the static fields ``K^-1 b`` lie in the
  basis); the transient error is that of the truncated modes above the band, measured against
  the dense plant in ``tests/test_control_closed_loop.py`` (7x31, LQG bending: shape-error
  histories within 1e-3 with the default 10 kHz band, 2e-2 with 3 kHz). Used on meshes where a
  dense ``2n x 2n`` exponential is too slow (25x121: 6534 states).

``"auto"`` picks ``"dense"`` up to 1000 dofs (7x31, 13x61) and ``"modal"`` above.
"""

from __future__ import annotations

import logging
import time
import weakref

import numpy as np

from wingopt.dynamics import zoh
from wingopt.dynamics.reduction import ReducedModel, reduced_basis
from wingopt.errors import InputError

__all__ = ["DensePlant", "ModalPlant", "make_plant", "DENSE_PLANT_MAX_DOFS", "DEFAULT_PLANT_BAND_HZ"]

log = logging.getLogger(__name__)

DENSE_PLANT_MAX_DOFS = 1000
"""``plant="auto"`` uses the dense exact plant up to this many dofs, the modal one above."""

DEFAULT_PLANT_BAND_HZ = 10000.0
"""Upper end of the modal plant's band (Hz); the static correction covers the rest exactly at DC."""


class DensePlant:
    """Exact ZOH of the full first-order model ``x = [z; z']`` (dense ``2n x 2n`` transition)."""

    kind = "dense"

    def __init__(self, model, dt: float) -> None:
        t0 = time.perf_counter()
        ss = model.system.state_space()
        self.F, self.G = zoh(ss.A, ss.B, dt)
        self.n = model.n
        self.dt = dt
        self.build_seconds = time.perf_counter() - t0
        log.info("dense plant: %d states, exact ZOH at %g s in %.2f s", 2 * self.n, dt, self.build_seconds)

    @property
    def description(self) -> str:
        return f"dense exact ZOH, {2 * self.n} states"

    def initial_state(self, z0: np.ndarray, zdot0: np.ndarray) -> np.ndarray:
        return np.concatenate([z0, zdot0])

    def step(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.F @ x + self.G @ u

    def fields(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return x[: self.n], x[self.n :]


class ModalPlant:
    """Exact ZOH of the modal model ``z = V q`` (modes below ``band_hz`` + static correction).

    ``q'' + V^T Kd V q' + diag(omega^2) q = V^T b u`` with the full projected damping matrix.
    """

    kind = "modal"

    def __init__(self, model, dt: float, band_hz: float = DEFAULT_PLANT_BAND_HZ, max_modes: int = 1500) -> None:
        t0 = time.perf_counter()
        n = model.n
        count = min(max_modes, n - model.n_inputs - 1)
        omega_all, _ = model.system.undamped_modes(count)
        n_modes = max(int(np.count_nonzero(omega_all <= 2 * np.pi * band_hz)), 1)
        if n_modes == count and count < n - model.n_inputs - 1:
            log.warning(
                "modal plant: %d modes do not reach %g Hz (highest %.0f Hz)",
                count,
                band_hz,
                omega_all[-1] / (2 * np.pi),
            )
        red = ReducedModel.from_basis(model.system, *reduced_basis(model.system, n_modes, "ritz"))
        disc = red.discretize(dt)
        self.F, self.G = disc.A, disc.B
        self.V = red.basis
        self.mass = model.mass
        self.r = red.size
        self.n_modes = n_modes
        self.band_hz = float(band_hz)
        self.dt = dt
        self.build_seconds = time.perf_counter() - t0
        log.info(
            "modal plant: %d modes below %g Hz + %d static vectors, exact ZOH at %g s in %.2f s",
            n_modes,
            band_hz,
            self.r - n_modes,
            dt,
            self.build_seconds,
        )

    @property
    def description(self) -> str:
        return f"modal exact ZOH, {self.n_modes} modes <= {self.band_hz:g} Hz + {self.r - self.n_modes} static vectors"

    def initial_state(self, z0: np.ndarray, zdot0: np.ndarray) -> np.ndarray:
        # M-orthogonal projection onto span V (exact for fields in the span, e.g. from rest).
        return np.concatenate([self.V.T @ (self.mass @ z0), self.V.T @ (self.mass @ zdot0)])

    def step(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.F @ x + self.G @ u

    def fields(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.V @ x[: self.r], self.V @ x[self.r :]


_PLANTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def make_plant(model, dt: float, kind: str = "auto", band_hz: float = DEFAULT_PLANT_BAND_HZ):
    """The exact-ZOH plant of ``model`` at step ``dt`` (cached per model, kind, step and band).

    Parameters
    ----------
    kind : {"auto", "dense", "modal"}
        ``"auto"``: dense up to :data:`DENSE_PLANT_MAX_DOFS` dofs, modal above.
    band_hz : float
        Band of the modal plant (ignored by the dense one).
    """
    if kind not in ("auto", "dense", "modal"):
        raise InputError(f"plant = {kind!r}: expected auto, dense or modal")
    if kind == "auto":
        kind = "dense" if model.n <= DENSE_PLANT_MAX_DOFS else "modal"
    key = (kind, round(float(dt), 15), float(band_hz) if kind == "modal" else None)
    cache = _PLANTS.setdefault(model, {})
    if key not in cache:
        cache[key] = DensePlant(model, dt) if kind == "dense" else ModalPlant(model, dt, band_hz)
    return cache[key]
