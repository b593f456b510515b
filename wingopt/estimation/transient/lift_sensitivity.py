"""The lift's sensitivity to a record fit's unknowns: what its band and its convergence test read."""

from __future__ import annotations

import numpy as np

from wingopt.estimation.core.record_problem import RecordProblem

__all__ = ["lift_jacobian"]


def lift_jacobian(rp: RecordProblem, c: np.ndarray, amp: np.ndarray) -> np.ndarray:
    """``d lift_k / d theta`` ``(N, dim)`` at the load history ``(c, amp)`` (:meth:`RecordProblem.load_history`).

    The lift is ``amp_k * (l . c)``: its shape part is ``amp_k l * std_c`` (the coefficients are
    scaled by their prior std), its gust part ``(l . c)`` times the gust's hat row.
    """
    shapes = rp.shapes
    G = np.zeros((rp.t.size, rp.dim))
    G[:, rp.slices["c"]] = amp[:, None] * (shapes.lift_row * shapes.prior_std)[None]
    if rp.hats is not None:
        G[:, rp.slices["g"]] = float(shapes.lift_row @ c) * rp.hats
    return G
