"""Linearised Bayesian design criteria: A-optimal (L2 load error), lift variance, D-optimal.

With the unknowns ``theta = [q0, q0', u]`` (nuisance initial state, modal load), a Gaussian prior of
precision ``Pi = blkdiag(state prior, (Cov u)^-1)`` and the information ``F(w) = sum_i w_i F_i`` of
the chosen sensors, the posterior covariance is ``(Pi + F)^-1``. In whitened coordinates
``theta = L t`` (``L^T Pi L = I``, ``F~_i = L^T F_i L``):

* **A** — expected squared L2 load error ``E||f - f^||^2 = tr(G Cov f|u) + tr(V~ (I + F~)^-1)``
  with ``V~ = Y^T G Y``, ``Y = Cov f B^T (Cov u)^-1/2`` (the part of the load the modal forces
  determine) and ``G`` the Gram matrix: a ``matrix_frac``, convex in ``w``.
* **lift** — posterior variance of ``∫ P``: the same with ``V~ = y y^T``, ``y = Y^T l``.
* **D** — ``-log det(I + F~)`` (information gain in nats).

Values are reported *relative*: A and lift as the ratio of posterior to prior standard deviation
(``sqrt(E err^2 / tr(G Cov f))``; the prior has ratio 1), D in nats. Several nominal responses
(a robust design) are combined by their mean square (``mean``) or worst case (``max``), so the
relaxation's optimum, a bound on the mean square, is a bound on the reported value too.

For the convex relaxation the whitened problem is cut to the ``rank`` leading directions of the
summed candidate information (:meth:`LinearCriterion.reduced`), so the SDP stays small.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from wingopt.design.information import ModalSensitivity, SegmentInformation
from wingopt.design.priors import LoadPrior
from wingopt.design.stack import InfoStack, TransformedStack
from wingopt.errors import InputError

__all__ = ["LINEAR_CRITERIA", "LinearCriterion", "state_prior_std", "psd_sqrt", "reduced_value"]

LINEAR_CRITERIA = ("a", "lift", "d")


def psd_sqrt(P: np.ndarray, rel: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric square root and pseudo-inverse square root of a PSD matrix (tiny eigenvalues cut)."""
    w, V = sla.eigh(0.5 * (P + P.T))
    keep = w > rel * w.max()
    w = np.where(keep, w, 0.0)
    r = np.sqrt(w)
    ri = np.where(keep, 1.0 / np.where(keep, r, 1.0), 0.0)
    return (V * r) @ V.T, (V * ri) @ V.T


def state_prior_std(sens: ModalSensitivity, q0: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Weak ``1/omega`` prior std of the kept initial state: ``A/omega_j`` and ``A`` (``A = omega_1 |q0_1|``).

    The estimator's choice (equal energy per mode, amplitude from the data); here the amplitude
    comes from the expected initial bubble.
    """
    ms = sens.settings.state_modes
    A = scale * sens.omega[0] * max(abs(q0[0]), 1e-300)
    return np.concatenate([A / sens.omega[:ms], np.full(ms, A)])


@dataclass(eq=False)
class LinearCriterion:
    """A batched linear criterion over one or more nominal responses.

    ``info`` is ``(N, J, d, d)``: whitened information of every candidate for each of ``J`` nominal
    responses; :meth:`values` maps summed information ``(B, J, d, d)`` to criterion values ``(B,)``.
    """

    kind: str
    info: np.ndarray
    weight: np.ndarray  # (J, d, d): V~ (A, lift); unused for D
    const: np.ndarray  # (J,): layout-independent part (A, lift)
    scale: np.ndarray  # (J,): prior value (A, lift) for the relative value
    aggregate: str = "mean"

    @classmethod
    def build(
        cls,
        kind: str,
        sens: ModalSensitivity,
        infos: list[SegmentInformation] | InfoStack,
        prior: LoadPrior,
        q0: np.ndarray,
        aggregate: str = "mean",
        state_prior: float = 1.0,
    ) -> LinearCriterion:
        """Whiten the information of each nominal response with ``prior`` and the state prior.

        ``infos``: a list of :class:`SegmentInformation`, or the risk's
        :class:`~wingopt.design.stack.InfoStack` (then read through a
        :class:`~wingopt.design.stack.TransformedStack`: no second copy of the information)."""
        if kind not in LINEAR_CRITERIA:
            raise InputError(f"criterion = {kind!r}: expected one of {', '.join(LINEAR_CRITERIA)}")
        if aggregate not in ("mean", "max"):
            raise InputError(f"aggregate = {aggregate!r}: expected 'mean' or 'max'")
        model = sens.model
        B = sens.input_matrix
        Pu = prior.modal_cov(B)
        Ph, Pih = psd_sqrt(Pu)
        ss = state_prior_std(sens, q0, state_prior)
        L = sla.block_diag(np.diag(ss), Ph)
        G = model.gram.toarray()
        Y = prior.cov @ B.T @ Pih  # (n_f, m)
        ms2 = 2 * sens.settings.state_modes
        d = sens.dim
        W = np.zeros((d, d))
        if kind == "a":
            W[ms2:, ms2:] = Y.T @ G @ Y
            prior_val = float(np.trace(G @ prior.cov))
        else:
            ell = model.basis_integrals
            y = Y.T @ ell
            W[ms2:, ms2:] = np.outer(y, y)
            prior_val = float(ell @ prior.cov @ ell)
        const = prior_val - float(np.trace(W))
        if isinstance(infos, InfoStack):  # the risk's packed information: whitened anew when read
            info = TransformedStack(infos, 1, L / infos.scale[:, None])
            J = infos.shape[1]
        else:
            info = np.stack([L.T @ inf.total @ L for inf in infos], axis=1)
            J = len(infos)
        return cls(
            kind, info, np.broadcast_to(W, (J, d, d)).copy(), np.full(J, const), np.full(J, prior_val), aggregate
        )

    @property
    def count(self) -> int:
        return len(self.info)

    def per_nominal(self, sums: np.ndarray) -> np.ndarray:
        """``(B, J)`` for summed whitened information ``(B, J, d, d)``: the *squared* relative error
        (A, lift) or ``-log det`` (D)."""
        eye = np.eye(sums.shape[-1])
        A = sums + eye
        if self.kind == "d":
            return -np.linalg.slogdet(A)[1]
        X = np.linalg.solve(A, np.broadcast_to(self.weight, A.shape))
        tr = np.trace(X, axis1=-2, axis2=-1)
        return np.maximum(self.const + tr, 0.0) / self.scale

    def values(self, sums: np.ndarray, sensors: int | None = None) -> np.ndarray:
        """Aggregated values ``(B,)``: A and lift the root mean (or max) square relative error over the
        nominal responses, D the mean (or max) of ``-log det`` (``sensors`` is unused)."""
        v = self.per_nominal(sums)
        v = v.mean(axis=1) if self.aggregate == "mean" else v.max(axis=1)
        return v if self.kind == "d" else np.sqrt(v)

    def layout_sum(self, index) -> np.ndarray:
        return self.info[np.asarray(index, dtype=int)].sum(axis=0)

    def value(self, index) -> float:
        return float(self.values(self.layout_sum(index)[None])[0])

    def reduced(self, rank: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """Reduction for the SDP to at most ``rank`` whitened directions per nominal response.

        A and lift: the leading eigenvectors ``U`` of the weight ``V~``. Since
        ``U^T (I + F)^-1 U >= (U^T (I + F) U)^-1`` and dropped parts of ``V~`` only add, the reduced
        criterion is a *lower bound* of the full one for every layout, so the relaxation of the
        reduced problem still bounds every K-subset (more loosely: the cut ignores how the nuisance
        initial state and the other directions share the information). D: the leading directions of
        the summed candidate information (an approximation, not a bound).

        Returns ``info_r`` ``(N, J, r, r)``, ``weight_r`` ``(J, r, r)``, ``const_r`` ``(J,)`` and the
        dropped fraction (of ``tr V~`` for A/lift, of the information trace for D).
        """
        N, J, d, _ = self.info.shape
        r = min(rank, d)
        info_r = np.empty((N, J, r, r))
        weight_r = np.zeros((J, r, r))
        const_r = self.const.copy()
        dropped = 0.0
        for j in range(J):
            if self.kind == "d":
                tot = sum(self.info[a : a + 256, j].sum(axis=0) for a in range(0, N, 256))
                w, U = sla.eigh(0.5 * (tot + tot.T))
                w, U = w[::-1], U[:, ::-1][:, :r]
                dropped = max(dropped, float(w[r:].sum() / max(w.sum(), 1e-300)))
            else:
                w, U = sla.eigh(self.weight[j])
                w, U = w[::-1], U[:, ::-1][:, :r]
                weight_r[j] = np.diag(np.maximum(w[:r], 0.0))
                dropped = max(dropped, float(np.maximum(w[r:], 0).sum() / max(w.sum(), 1e-300)))
            for a in range(0, N, 256):  # in chunks: the candidates' dense matrices do not fit at once
                info_r[a : a + 256, j] = U.T @ self.info[a : a + 256, j] @ U
        return info_r, weight_r, const_r, dropped


def reduced_value(linear: LinearCriterion, info_r, weight_r, const_r, layout) -> float:
    """The reduced criterion of a layout (what the relaxation bound is a bound of)."""
    S = info_r[np.asarray(layout)].sum(axis=0)  # (J, r, r)
    eye = np.eye(S.shape[-1])
    if linear.kind == "d":
        v = -np.linalg.slogdet(S + eye)[1]
        return float(v.mean() if linear.aggregate == "mean" else v.max())
    tr = np.trace(np.linalg.solve(S + eye, weight_r), axis1=-2, axis2=-1)
    v = (const_r + tr) / linear.scale
    return float(np.sqrt(v.mean() if linear.aggregate == "mean" else v.max()))
