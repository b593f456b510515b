"""Stretch sensors (eq. 4.41, App. B.1): ``s_i = alpha/(2 A_i) ∫_{S_i} (w_x^2 + w_y^2) = z^T C_i z``."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from wingopt.errors import InputError
from wingopt.fe import BilinearForm, TensorSpace, assemble
from wingopt.problem.membrane import StretchSensorSpec

__all__ = ["StretchSensors", "stretch_form", "noise_std_for", "add_noise"]


@BilinearForm
def stretch_form(u, v, w):
    """``alpha/(2A) (phi_x phi_x^T + phi_y phi_y^T)`` on the sensor's rectangle."""
    return w.scale * (u.dx * v.dx + u.dy * v.dy)


@dataclass(frozen=True, eq=False)
class StretchSensors:
    """A set of stretch sensors on a space: names, rectangles and their matrices ``C_i``.

    Sensors are quadratic in the deflection and therefore sign-blind: ``z`` and ``-z`` give the
    same outputs.
    """

    names: tuple[str, ...]
    rects: tuple[tuple[float, float, float, float], ...]
    matrices: tuple[sp.csr_matrix, ...]

    @classmethod
    def assemble(cls, space: TensorSpace, specs: Sequence[StretchSensorSpec]) -> StretchSensors:
        """Exact ``C_i`` for any rectangles (quadrature split at the rectangle edges)."""
        mats = []
        for s in specs:
            space.check_rect(s.rect, name=f"sensor {s.name} rect")
            x0, x1, y0, y1 = s.rect
            scale = s.gain / (2.0 * (x1 - x0) * (y1 - y0))
            mats.append(assemble(space, stretch_form, space.cells(s.rect), data={"scale": scale}))
        return cls(tuple(s.name for s in specs), tuple(tuple(s.rect) for s in specs), tuple(mats))

    def __len__(self) -> int:
        return len(self.matrices)

    @property
    def stacked(self) -> np.ndarray:
        """Dense ``(p, n, n)`` array of all ``C_i``."""
        return np.stack([C.toarray() for C in self.matrices])

    def outputs(self, z: np.ndarray) -> np.ndarray:
        """``s_i = z^T C_i z`` for a field ``(n,)`` or a history ``(nt, n)`` -> ``(p,)`` or ``(nt, p)``."""
        z = np.asarray(z, dtype=float)
        Z = np.atleast_2d(z)
        out = np.stack([np.einsum("ij,ij->i", Z, (C @ Z.T).T) for C in self.matrices], axis=1)
        return out[0] if z.ndim == 1 else out

    def jacobian(self, z: np.ndarray) -> np.ndarray:
        """``(p, n)`` matrix of rows ``2 z^T C_i``."""
        return np.stack([2.0 * (C @ z) for C in self.matrices])


def noise_std_for(clean: np.ndarray, fraction: float) -> np.ndarray:
    """Per-sensor noise level ``sigma_i = fraction * max_t |s_i(t)|`` (spec §2)."""
    if not (np.isfinite(fraction) and fraction >= 0):
        raise InputError(f"noise = {fraction!r}: expected a non-negative fraction, e.g. 0.01 for 1 %")
    return fraction * np.max(np.abs(clean), axis=0)


def add_noise(clean: np.ndarray, fraction: float, seed: int | None) -> tuple[np.ndarray, np.ndarray]:
    """Seeded Gaussian noise, independent per sensor; returns ``(noisy, sigma)``."""
    sigma = noise_std_for(clean, fraction)
    rng = np.random.default_rng(seed)
    return clean + rng.standard_normal(clean.shape) * sigma, sigma
