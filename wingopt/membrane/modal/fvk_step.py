"""One sample of the cubic modal FvK membrane and its exact tangent, for the streaming (EKF) estimator.

The map is :meth:`~wingopt.membrane.modal.fvk.FvKModal.simulate` over one sample (the
batch estimator's integrator, predictor-corrector on the secant stiffness and the off-diagonal cubic
force), run by the compiled sub-step of :mod:`~wingopt.membrane.modal.kernels`; its
tangent is that kernel's. Same interface as
:class:`~wingopt.membrane.modal.berger_step.BergerSample`: directions are rows,
``dQ[j, i] = d q_i / d theta_j``; rows ``load_rows`` act through the modal force, rows
``par_rows`` through ``d ex, d ey, d damping``.
"""

from __future__ import annotations

import numpy as np

from wingopt.errors import InputError
from wingopt.membrane.modal.fvk import FvKModal
from wingopt.membrane.modal.kernels import fvk_step_tangent
from wingopt.membrane.modal.oscillator import prestress_terms

__all__ = ["FvKSample"]


class FvKSample:
    """One-sample map ``(q, v) -> (q', v')`` of a :class:`FvKModal` and its tangent.

    Parameters
    ----------
    fm : FvKModal
    load_forces : ndarray ``(ns, m)``
        Modal force per unit of each load unknown (its tangent seed).
    load_rows, par_rows : slice
        Rows of the direction arrays that are the load and the parameter unknowns.
    substeps : int, optional
        Sub-steps per sample (default: the model's).
    """

    def __init__(
        self, fm: FvKModal, load_forces: np.ndarray, load_rows: slice, par_rows: slice, substeps: int | None = None
    ) -> None:
        if not isinstance(fm, FvKModal):
            raise InputError(f"FvKSample: needs an FvKModal, got {type(fm).__name__}")
        self.fm, self.m = fm, fm.m
        self.substeps = fm.substeps if substeps is None else int(substeps)
        if self.substeps < 1:
            raise InputError(f"substeps = {substeps!r}: expected >= 1")
        self.h = fm.dt / self.substeps
        self.load_forces = np.asarray(load_forces, dtype=float)
        self.load_rows, self.par_rows = load_rows, par_rows
        self._tensors = (fm.cubic_modes, fm.pair_tensor, fm.diag_tensor)

    def step_tangent(
        self,
        q: np.ndarray,
        v: np.ndarray,
        u: np.ndarray,
        ex: float,
        ey: float,
        damping: float,
        dQ: np.ndarray,
        dV: np.ndarray,
        dpar: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """State one sample later and its tangents (arguments as ``BergerSample.step_tangent``:
        ``dQ, dV`` ``(P, m)`` seeds, ``dpar`` ``(3, npar)`` seeds of ``(ex, ey, damping)`` for the
        parameter rows)."""
        P, m = dQ.shape
        seeds = np.zeros((3, P))
        seeds[:, self.par_rows] = dpar
        du = np.zeros((m, P))
        du[:, self.load_rows] = self.load_forces.T
        q1, v1, dq1, dv1 = self._advance(q, v, u, ex, ey, damping, seeds, du, dQ.T, dV.T)
        return q1, v1, dq1.T, dv1.T

    def step(
        self, q: np.ndarray, v: np.ndarray, u: np.ndarray, ex: float, ey: float, damping: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """The state one sample later (no tangent)."""
        none = np.zeros((self.m, 0))
        q1, v1, _, _ = self._advance(q, v, u, ex, ey, damping, np.zeros((3, 0)), none, none, none)
        return q1, v1

    def _advance(self, q, v, u, ex, ey, damping, seeds, du, dq, dv):
        h, k0, dk0, a, da, e = prestress_terms(self.fm, ex, ey, damping, seeds, self.substeps)
        r, Tc, Bd = self._tensors
        c = np.ascontiguousarray
        return fvk_step_tangent(
            np.asarray(q, float), np.asarray(v, float), np.asarray(u, float), c(du), k0, c(dk0.T), a, c(da.T), e, h,
            self.substeps, r, Tc, Bd, c(dq, dtype=float), c(dv, dtype=float),
        )  # fmt: skip
