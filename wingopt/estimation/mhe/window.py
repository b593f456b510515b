"""One window of the moving-horizon estimator as a nonlinear least-squares problem.

The cost of the window unknowns ``theta = [q0, q0', u_1 .. u_B]`` (modal state at the window
start, modal forces of the ``B`` load blocks) is::

    V(theta) = sum_{k,i} w_{k,i} (y_{k,i} - h_{k,i}(theta))^2  +  theta^T H0 theta - 2 g0^T theta + c0

with ``w = 1/sigma_i^2`` (0 for a missing sample) and a quadratic part that collects the arrival
cost, the prior on the initial modal state, ``lambda u^T S^-1 u`` and the random-walk penalty.
``V`` is a chi-square: ``exp(-V/2)`` is the posterior density, so the Gauss–Newton matrix
``H = J^T W J + H0`` is the posterior precision of ``theta`` (Laplace approximation).

Optional linear inequality bounds ``lo <= A theta <= hi`` carry pressure bounds.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from wingopt.estimation.mhe.model import MHEModel, WindowBasis

__all__ = ["WindowProblem", "LinearBounds"]


@dataclass(frozen=True, eq=False)
class LinearBounds:
    """``lo <= A theta <= hi`` (rows may be infinite on one side)."""

    A: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    def violation(self, theta: np.ndarray) -> float:
        v = self.A @ theta
        return float(max(np.max(self.lo - v, initial=0.0), np.max(v - self.hi, initial=0.0)))


@dataclass(eq=False)
class WindowProblem:
    """Data, weights and quadratic terms of one window (physical modal units).

    Attributes
    ----------
    reduced : MHEModel
    basis : WindowBasis
    y, w : ndarray ``(length, p)``
        Data (missing samples set to 0) and weights (0 where missing).
    H0, g0, c0 : quadratic part ``theta^T H0 theta - 2 g0^T theta + c0``.
    scale : ndarray ``(dim,)``
        Typical magnitude of each unknown; solvers work with ``theta / scale``.
    bounds : LinearBounds or None
    """

    reduced: MHEModel
    basis: WindowBasis
    y: np.ndarray
    w: np.ndarray
    H0: np.ndarray
    g0: np.ndarray
    c0: float
    scale: np.ndarray
    bounds: LinearBounds | None = None
    _seq: list = field(default_factory=list, repr=False)

    @property
    def dim(self) -> int:
        return self.H0.shape[0]

    @property
    def n_data(self) -> int:
        return int(np.count_nonzero(self.w))

    # -- cost and derivatives ---------------------------------------------------------------
    def predict(self, theta: np.ndarray) -> np.ndarray:
        """Sensor outputs ``(length, p)`` of ``theta``."""
        return self.reduced.outputs(self.reduced.modal_trajectory(self.basis, theta))

    def data_cost(self, theta: np.ndarray) -> float:
        r = self.y - self.predict(theta)
        return float(np.sum(self.w * r * r))

    def prior_cost(self, theta: np.ndarray) -> float:
        return float(theta @ (self.H0 @ theta) - 2.0 * self.g0 @ theta + self.c0)

    def cost(self, theta: np.ndarray) -> float:
        """``V(theta)``; ``inf`` if it overflows."""
        with np.errstate(over="ignore", invalid="ignore"):
            v = self.data_cost(theta) + self.prior_cost(theta)
        return v if np.isfinite(v) else np.inf

    def linearize(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Weighted residual ``(n,)`` and Jacobian ``(n, dim)`` rows of the data term.

        Rows are ``sqrt(w) (y - h)`` and ``sqrt(w) dh/dtheta``: ``H = J^T J + H0``,
        half-gradient ``J^T r - H0 theta + g0``.
        """
        Y, J = self.reduced.outputs_and_jacobian(self.basis, theta)
        sw = np.sqrt(self.w)
        r = (sw * (self.y - Y)).ravel()
        Jw = (J * sw[:, :, None]).reshape(-1, J.shape[2])
        return r, Jw

    def normal_equations(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gauss–Newton matrix ``H`` and half-gradient ``b`` (step: ``H d = b``)."""
        r, J = self.linearize(theta)
        H = J.T @ J + self.H0
        b = J.T @ r - self.H0 @ theta + self.g0
        return 0.5 * (H + H.T), b

    def log_evidence(self, theta: np.ndarray) -> float:
        """Laplace (Gauss–Newton) log marginal likelihood of the window's data at the optimum ``theta``.

        The quadratic part is read as a Gaussian prior with precision ``H0`` and mean
        ``H0^-1 g0`` (its own constant ``g0^T H0^-1 g0`` replaces ``c0``, so the value does not
        depend on how ``c0`` was set), which needs ``H0`` positive definite (the first window:
        state prior + ``lambda S^-1``). Returned up to ``-n/2 log 2 pi - sum log sigma``, which is
        the same for every prior on the same data::

            log Z = -1/2 [chi2 + (theta - mu)^T H0 (theta - mu)] - 1/2 log det(H) / det(H0)

        with ``H = J^T W J + H0``. Computed in the scaled unknowns (the scale cancels in the ratio).
        """
        D = self.scale
        _, J = self.linearize(theta)
        H0s = D[:, None] * self.H0 * D[None, :]
        H0s = 0.5 * (H0s + H0s.T)
        Js = J * D[None, :]
        c0 = sla.cho_factor(H0s)
        mu_s = sla.cho_solve(c0, D * self.g0)
        d = theta / D - mu_s
        prior = float(d @ (H0s @ d))
        ch = sla.cho_factor(Js.T @ Js + H0s)
        logdet_ratio = 2.0 * (np.sum(np.log(np.diag(ch[0]))) - np.sum(np.log(np.diag(c0[0]))))
        return -0.5 * (self.data_cost(theta) + prior) - 0.5 * logdet_ratio

    def second_order(self, theta: np.ndarray) -> np.ndarray:
        """``-sum w r d2h/dtheta2`` (half-cost units): exact Hessian = ``H_GN`` + this.

        ``d2h_{k,i} = 2 P_k^T C^_i P_k`` with ``P_k = dq_k/dtheta = [diag(a_k), diag(b_k),
        diag(c_{k,b})..]``, so every block is ``C^_i ⊙ (sum_k rho_k alpha_k beta_k^T)``.
        """
        red, basis = self.reduced, self.basis
        rho = self.w * (self.y - self.predict(theta))
        seqs = [basis.a, basis.b] + [basis.c[b] for b in range(basis.blocks)]
        m, p, N = red.m, red.p, basis.length
        out = np.zeros((self.dim, self.dim))
        for i in range(len(seqs)):
            # rho-weighted sequences of all sensors side by side: one product per block pair.
            left = (seqs[i][:, None, :] * rho[:, :, None]).reshape(N, p * m)
            for j in range(i, len(seqs)):
                R = (left.T @ seqs[j]).reshape(p, m, m)
                blk = np.einsum("pab,pab->ab", red.sensor_matrices, R, optimize=True)
                out[i * m : (i + 1) * m, j * m : (j + 1) * m] = blk
                if i != j:
                    out[j * m : (j + 1) * m, i * m : (i + 1) * m] = blk.T
        return -2.0 * out
