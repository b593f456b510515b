"""Bias-aware design criterion: the expected error of the estimator the package actually runs.

The plain A-criterion assumes the Bayes estimator of its own prior. The MHE is not that: it
fits a Tikhonov estimate whose weight ``lambda`` is chosen from the data (the misfit knee of
:mod:`wingopt.estimation.core.regularization`), in a fixed-edge load space, so its error is mostly
*bias*. For a nominal pressure ``P`` (projection ``f`` onto the load space) and a layout, the
linearised estimate is ``f^ = A_lambda f + noise`` with the resolution operator
``A_lambda = (B^T H B + lambda Lam)^-1 B^T H B`` (``H``: the layout's information on the modal load
after eliminating the initial state), and the expected squared error is::

    ||P - f||^2            representation (layout-independent)
  + ||(I - A_lambda) f||^2  Tikhonov bias (what the sensors do not resolve)
  + tr(G Cov f^)            noise

with ``lambda`` the value the estimator's rule would pick: on the first window's information the
misfit increase of the noise-free bias plus the expected noise term ``sum (1 - h_k)^2`` crosses
``0.5 sqrt(2 n)`` at the knee, and the rule takes the knee / 3. Everything reduces to ``m x m``
algebra: with ``Lam = R^T R`` and the thin SVD ``B R^-1 = U S V^T`` the load enters only through
``c = V^T R f``; the part of ``R f`` outside ``V`` is never resolved.

The criterion is the mean relative error ``sqrt(E err^2) / ||P||`` over a family of nominal loads
(each linearised along its own response: the sensors' nonlinearity enters through the family).
It does not see local minima or sign errors: :mod:`wingopt.design.montecarlo` runs the estimator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from wingopt.design.criteria import state_prior_std
from wingopt.design.information import ModalSensitivity, SegmentInformation
from wingopt.design.stack import InfoStack, dense_stack
from wingopt.estimation.core.regularization import KNEE_EXCESS, KNEE_SAFETY
from wingopt.fe import integrate

__all__ = ["BayesRisk"]

_LAM_GRID = 10.0 ** np.arange(-6.0, 0.01, 0.125)
"""Relative lambda grid: multiples of the natural scale, the estimator's range (1e-6..1)."""


@dataclass(eq=False)
class BayesRisk:
    """Batched bias + variance criterion over ``J`` nominal loads.

    ``info`` ``(N, J, 2, d, d)``: per candidate and nominal, the information of the first window and
    of the whole record (state part whitened by the state prior).
    """

    info: InfoStack
    m: int
    ms2: int
    US: np.ndarray  # (m, m): U_c S_c
    c0: np.ndarray  # (J, m)
    a0: np.ndarray  # (J,): ||unresolvable part||^2 + representation error
    b0: np.ndarray  # (J, m)
    Gc: np.ndarray  # (m, m)
    norm2: np.ndarray  # (J,): ||P||^2
    window_samples: int
    smooth: np.ndarray  # (m,): c of the smoothest load shape, unit ||R f||
    coef_map: np.ndarray  # (n_f, m): f = R^-1 V c
    aggregate: str = "mean"

    @classmethod
    def build(
        cls,
        sens: ModalSensitivity,
        infos: list[SegmentInformation] | InfoStack,
        loads,
        q0: np.ndarray,
        aggregate: str = "mean",
        state_prior: float = 1.0,
    ) -> BayesRisk:
        """``loads``: the nominal pressures (callables), one per entry of ``infos`` (a list of
        :class:`SegmentInformation`, or the :class:`~wingopt.design.stack.InfoStack` of
        :func:`~wingopt.design.stack.information_stack`, whitened with ``state_prior`` 1)."""
        model = sens.model
        ms2 = 2 * sens.settings.state_modes
        # The information, packed (wingopt.design.stack): built here from a list, or given as a stack.
        if not isinstance(infos, InfoStack):
            infos = dense_stack(infos, np.concatenate([state_prior_std(sens, q0, state_prior), np.ones(sens.m)]))
        info = infos
        Lam = model.regularizer.toarray()
        R = sla.cholesky(0.5 * (Lam + Lam.T))  # Lam = R^T R
        C = sla.solve_triangular(R, sens.input_matrix.T, trans="T").T  # B R^-1, (m, n_f)
        U, s, Vt = sla.svd(C, full_matrices=False)
        V = Vt.T
        M = model.gram.toarray()
        Rinv = sla.solve_triangular(R, np.eye(R.shape[0]))
        Gt = Rinv.T @ M @ Rinv
        Gc = V.T @ Gt @ V
        # The smoothest load shape (least Lam per Gram): the estimator's natural lambda scale.
        _, ev = sla.eigh(0.5 * (Lam + Lam.T), M, subset_by_index=[0, 0])
        gs = R @ ev[:, 0]
        smooth = V.T @ (gs / np.linalg.norm(gs))
        c0s, a0s, b0s, norms = [], [], [], []
        for P in loads:
            f = model.project(P)
            g = R @ f
            c = V.T @ g
            gp = g - V @ c
            norm2 = integrate(model.space, lambda x, y, P=P: P(x, y) ** 2, order=8)
            rep = max(norm2 - f @ (M @ f), 0.0)
            c0s.append(c)
            a0s.append(gp @ Gt @ gp + rep)
            b0s.append(V.T @ (Gt @ gp))
            norms.append(norm2)
        return cls(
            info,
            sens.m,
            ms2,
            U * s,
            np.array(c0s),
            np.array(a0s),
            np.array(b0s),
            Gc,
            np.array(norms),
            sens.window_samples,
            smooth,
            Rinv @ V,
            aggregate,
        )

    @property
    def count(self) -> int:
        return len(self.info)

    def _load_information(self, F: np.ndarray) -> np.ndarray:
        """Schur complement on the modal load, state prior added: ``(B, m, m)``."""
        k = self.ms2
        Fss = F[..., :k, :k] + np.eye(k)
        Fsu = F[..., :k, k:]
        H = F[..., k:, k:] - np.swapaxes(Fsu, -1, -2) @ np.linalg.solve(Fss, Fsu)
        Q = np.swapaxes(self.US, 0, 1) @ H @ self.US
        return 0.5 * (Q + np.swapaxes(Q, -1, -2))

    def _rule_lambda(self, Qw: np.ndarray, c0: np.ndarray, sensors: int) -> np.ndarray:
        """The knee rule on the first window: ``(B,)`` lambdas.

        The grid is the estimator's, relative to the natural scale ``v^T Q v`` of the smoothest load
        shape ``v``; the floor is the least misfit on the grid (so weakly seen directions below the
        grid's smallest lambda do not count, as in the estimator).
        """
        s2, Vw = np.linalg.eigh(Qw)
        s2 = np.maximum(s2, 0.0)
        cw = c0 @ Vw  # (B, m): Vw^T c0
        nat = ((Qw @ self.smooth) @ self.smooth)[:, None]
        lam = nat * _LAM_GRID[None, :]  # (B, L)
        r = lam[:, :, None] / (s2[:, None, :] + lam[:, :, None])  # 1 - h, (B, L, m)
        bias = np.sum(s2[:, None, :] * r**2 * cw[:, None, :] ** 2, axis=-1)
        noise = np.sum(r**2, axis=-1)
        chi = bias + noise
        thr = chi.min(axis=1, keepdims=True) + KNEE_EXCESS * np.sqrt(2.0 * self.window_samples * sensors)
        above = chi > thr
        first = np.where(above.any(axis=1), above.argmax(axis=1), lam.shape[1] - 1)
        first = np.maximum(first, 1)
        rows = np.arange(lam.shape[0])
        # Geometric interpolation of the crossing, as the estimator does on its grid.
        x0, x1 = np.log(lam[rows, first - 1]), np.log(lam[rows, first])
        y0, y1 = chi[rows, first - 1], chi[rows, first]
        t = np.clip((thr[:, 0] - y0) / np.where(y1 > y0, y1 - y0, 1.0), 0.0, 1.0)
        knee = np.exp(x0 + t * (x1 - x0))
        return knee / KNEE_SAFETY

    def rule_lambdas(self, sums: np.ndarray, sensors: int) -> np.ndarray:
        """The emulated rule's lambda ``(B, J)`` (weight of ``f^T Lam f``, data in noise units)."""
        return np.stack(
            [
                self._rule_lambda(self._load_information(sums[:, j, 0]), self.c0[j], sensors)
                for j in range(sums.shape[1])
            ],
            axis=1,
        )

    def estimate(self, index) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free linearised estimates of every nominal load, as coordinates ``c`` ``(J, m)`` in
        ``V`` (``f^ = R^-1 V c``), and the lambdas ``(J,)``; see :meth:`load_coefficients`."""
        index = np.atleast_1d(np.asarray(index, dtype=int))
        S = self.layout_sum(index)[None]
        out, lams = [], []
        for j in range(S.shape[1]):
            lam = self._rule_lambda(self._load_information(S[:, j, 0]), self.c0[j], index.size)[0]
            s2, Vx = np.linalg.eigh(self._load_information(S[:, j, 1])[0])
            s2 = np.maximum(s2, 0.0)
            out.append(Vx @ (s2 / (s2 + lam) * (Vx.T @ self.c0[j])))
            lams.append(lam)
        return np.array(out), np.array(lams)

    def load_coefficients(self, index) -> np.ndarray:
        """Noise-free linearised estimates ``(J, n_f)`` of the nominal loads by the layout ``index``."""
        c, _ = self.estimate(index)
        return c @ self.coef_map.T

    def per_nominal(self, sums: np.ndarray, sensors: int) -> np.ndarray:
        """Relative expected errors ``(B, J)`` for summed information ``(B, J, 2, d, d)``."""
        B, J = sums.shape[:2]
        out = np.empty((B, J))
        for j in range(J):
            Qw = self._load_information(sums[:, j, 0])
            Qt = self._load_information(sums[:, j, 1])
            lam = self._rule_lambda(Qw, self.c0[j], sensors)
            s2, Vx = np.linalg.eigh(Qt)
            s2 = np.maximum(s2, 0.0)
            ct = self.c0[j] @ Vx  # (B, m)
            h = s2 / (s2 + lam[:, None])
            delta = self.c0[j][None, :] - (Vx @ (h * ct)[:, :, None])[:, :, 0]
            bias2 = self.a0[j] + 2.0 * delta @ self.b0[j] + np.sum((delta @ self.Gc) * delta, axis=1)
            gdiag = np.sum(Vx * (self.Gc @ Vx), axis=1)  # diag(Vx^T Gc Vx)
            var = np.sum(s2 / (s2 + lam[:, None]) ** 2 * gdiag, axis=-1)
            out[:, j] = np.sqrt(np.maximum(bias2 + var, 0.0) / self.norm2[j])
        return out

    def values(self, sums: np.ndarray, sensors: int | None = None) -> np.ndarray:
        sensors = 4 if sensors is None else sensors
        v = self.per_nominal(sums, sensors)
        return v.mean(axis=1) if self.aggregate == "mean" else v.max(axis=1)

    def layout_sum(self, index) -> np.ndarray:
        return self.info.sum(index)

    def value(self, index) -> float:
        index = np.atleast_1d(np.asarray(index, dtype=int))
        return float(self.values(self.layout_sum(index)[None], len(index))[0])
