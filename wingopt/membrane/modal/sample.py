"""One sample of a modal membrane and its exact tangent, for the streaming (EKF) estimator.

The map is the model's :meth:`~wingopt.membrane.modal.base.ModalMembrane.simulate` over one sample
(the batch estimator's integrator: the one compiled loop of :mod:`.kernels` with the model's force
law, Berger or FvK), with the velocity tangents too. Directions are rows,
``dQ[j, i] = d q_i / d theta_j``: rows ``load_rows`` are unit directions of the load unknowns (they
act through the modal force), rows ``par_rows`` those of the parameters (through ``d ex, d ey,
d damping``); the state part of every row is whatever the caller seeds.
"""

from __future__ import annotations

import numpy as np

from wingopt.errors import InputError
from wingopt.membrane.modal.base import ModalMembrane
from wingopt.membrane.modal.kernels import step_tangent

__all__ = ["ModalSample"]


class ModalSample:
    """One-sample map ``(q, v) -> (q', v')`` of a modal membrane and its tangent.

    Parameters
    ----------
    bm : ModalMembrane
        A :class:`~.berger.BergerModal` or :class:`~.fvk.FvKModal`.
    load_forces : ndarray ``(ns, m)``
        Modal force per unit of each load unknown (its tangent seed).
    load_rows, par_rows : slice
        Rows of the direction arrays that are the load and the parameter unknowns.
    substeps : int, optional
        Sub-steps per sample (default: the model's).

    Attributes
    ----------
    nonlinear : bool
        ``False`` leaves the deflection's own stiffening out (the linear membrane; tests).
    """

    def __init__(
        self,
        bm: ModalMembrane,
        load_forces: np.ndarray,
        load_rows: slice,
        par_rows: slice,
        substeps: int | None = None,
    ) -> None:
        if not isinstance(bm, ModalMembrane):
            raise InputError(f"ModalSample: needs a modal membrane, got {type(bm).__name__}")
        self.bm, self.m = bm, bm.m
        self.substeps = bm.substeps if substeps is None else substeps
        if not (isinstance(self.substeps, (int, np.integer)) and self.substeps >= 1):
            raise InputError(f"substeps = {substeps!r}: expected an integer >= 1")
        self.load_forces = np.asarray(load_forces, dtype=float)
        self.load_rows, self.par_rows = load_rows, par_rows
        self.nonlinear = True

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
        """State one sample later and its tangents.

        Parameters
        ----------
        q, v, u : ``(m,)`` displacement, velocity and the modal force held over the sample
        ex, ey, damping : float
        dQ, dV : ``(P, m)`` seeds of ``q, v`` (not modified)
        dpar : ``(3, npar)`` seeds of ``(ex, ey, damping)`` for the parameter rows

        Returns
        -------
        q1, v1 : ``(m,)``; dQ1, dV1 : ``(P, m)``
        """
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
        """The state one sample later (no tangent; the same arithmetic as :meth:`step_tangent`'s state)."""
        none = np.zeros((self.m, 0))
        q1, v1, _, _ = self._advance(q, v, u, ex, ey, damping, np.zeros((3, 0)), none, none, none)
        return q1, v1

    def _advance(self, q, v, u, ex, ey, damping, seeds, du, dq, dv):
        h, k0, dk0, a, da, e = self.bm.linear_terms(ex, ey, damping, seeds, self.substeps)
        c = np.ascontiguousarray
        q, v, u = np.asarray(q, float), np.asarray(v, float), np.asarray(u, float)
        terms = (k0, c(dk0.T), a, c(da.T), e, h, int(self.substeps), self.bm.force_law(self.nonlinear))
        return step_tangent(q, v, u, c(du), *terms, c(dq, dtype=float), c(dv, dtype=float))
