"""Small DIC frames from closed-form fields (no simulation) and a calibrated prior, shared by the DIC tests."""

import dataclasses

import numpy as np

from wingopt.measurements.dic import DICFrames
from wingopt.membrane.dic_synth import dic_grid

W, H = 0.14, 0.07


def analytic_frames(n_frames: int = 6, grid=(12, 6), missing: float = 0.0, seed: int = 0) -> DICFrames:
    """A bubble growing in time, with in-plane displacements and surface strains of its own."""
    x, y = dic_grid(W, H, grid)
    t = np.arange(n_frames) / 300.0
    a = 0.004 * (1 + 0.1 * np.arange(n_frames))[:, None]
    sx, sy = np.sin(np.pi * x / W), np.sin(np.pi * y / H)
    w = a * sx * sy
    u = 1e-2 * a * np.sin(2 * np.pi * x / W) * sy
    v = 1e-2 * a * sx * np.sin(2 * np.pi * y / H)
    wx, wy = a * np.pi / W * np.cos(np.pi * x / W) * sy, a * np.pi / H * sx * np.cos(np.pi * y / H)
    exx, eyy, exy = 0.5 * wx**2 + 1e-4, 0.5 * wy**2 - 1e-4, 0.5 * wx * wy
    valid = np.random.default_rng(seed).random(w.shape) >= missing
    return DICFrames(x, y, t, u, v, w, exx, eyy, exy, valid, source="analytic")


def calibrated(problem, e0, offset=(1.024, 0.991), rel=(0.040, 0.037), corr=-0.95):
    """The problem with a calibration's posterior as its [identification] prior: prestrains ``offset``
    off the truth ``e0`` with relative stds ``rel`` and correlation ``corr`` (a ringing record's)."""
    ident = dataclasses.replace(
        problem.identification,
        prestrain=(e0[0] * offset[0], e0[1] * offset[1]),
        prestrain_std=(rel[0] * e0[0], rel[1] * e0[1]),
        prestrain_correlation=corr,
        calibration="test",
    )
    return dataclasses.replace(problem, identification=ident)
