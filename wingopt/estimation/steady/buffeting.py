"""The tension from buffeting: the static mean and the fluctuation's spectrum of a steady record, fitted jointly.

A wing in steady flow is loaded by ``(1 + eps(t)) P(x, y)``: the mean pressure (the static fit of
:mod:`.steady`) times a stationary load factor, the flow's buffeting. Linearised about the static
state ``q̄`` of the modal FvK model (:func:`~wingopt.membrane.forward.modal_model`, every mode of the
mesh, FvK's cubic stiffness on the lowest ``r``), the sensors' fluctuation is ``eps`` through

    h(w) = J (K_t - w^2 + i w C)^-1 u,    J_i = 2 q̄^T Ĉ_i,   u = Phi^T P (the mean load's modal force)

with the loaded tangent ``K_t = diag(k0) + 3 S(q̄)`` on the cubic block (dense ``r x r``: its
transfer from the ``2r`` state-space eigenpairs) and ``diag(k0)`` beyond it (uncoupled oscillators),
and the prestress damping ``C = d diag(gamma/rho h + eta (Tx0 kx + Ty0 ky))``. The loaded first
frequency depends on the tension *and* the load; the mean fixes the load for a given tension; the two
together identify the tension. The sampled sensors' cross-spectral matrix (two-sided, units²/Hz) is

    S(f) = sum_{|k| <= aliases} |H_k|^2 S_eps(f + k fs) h h^H + dt g(f) diag(sigma^2),  S_eps = A (1 + (f/fc)^2)^-n

(the forcing's spectrum and the noise floor are unknown). ``H_k = H(f + k fs)`` is the DAQ's anti-
aliasing filter (:class:`~wingopt.measurements.acquisition.Acquisition`, ``SpectralData.
acquisition``): 1 for point sampling, 0 on the aliases a digital filter removes; the noise comes
before the filter, ``g = sum_k |H_k|^2`` (1 for point sampling: wideband noise folded back). Its fit
to the binned periodograms ``Ī_b`` (:mod:`.spectra`) is Whittle's likelihood ``sum_b n_b [log det
S_b + tr(S_b^-1 Ī_b)]``. Fisher scoring on it is Gauss–Newton on the residuals ``sqrt(n_b) vec(W_b
(Ī_b - S_b(theta)) W_b^H)`` with the weights ``W_b = chol(S_b)^-1`` frozen at a point: their
gradient there is Whittle's score and ``J^T J`` its expected information. :class:`BuffetingProblem`
is that residual problem (with the static rows of :class:`~.steady.SteadyProblem` and the priors)
for :func:`~.solver.levenberg_marquardt`; the driver (:mod:`.buffeting_fit`) refreezes the weights
after every step (iteratively reweighted: the fixed point is Whittle's estimate). Every derivative
is analytic: the static sensitivities by implicit differentiation, the transfer's by ``dh = dJ x +
lambda^T (du - (dK_t + i w dC) x)``
(``x = G u``, ``lambda_i = G J_i^T``; ``G`` is complex symmetric).

Unknowns (scaled, every prior ``N(0, 1)``): the steady problem's (load shapes, free prestrains), the
log damping factor, and the nuisance ``log A`` (std 5 about a level from the data), ``log fc`` (about
30 Hz, std ``log 10``), ``n = 2 exp(theta/2)``, ``log sigma_i`` (std 2 about the spectra's floor).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.linalg as sla

from wingopt.errors import InputError, SolverError
from wingopt.estimation.steady.problem import SteadyProblem
from wingopt.estimation.steady.spectra import SpectralData

__all__ = ["BuffetingProblem", "NUISANCE"]

log = logging.getLogger(__name__)

NUISANCE = {"log_A": 5.0, "log_fc": float(np.log(10.0)), "order": 0.5, "log_sigma": 2.0}
"""Prior std of the nuisance unknowns (scaled: ``x = x_ref + std theta``; the order ``n = 2 exp(std theta)``)."""

FC_REF, ORDER_REF = 30.0, 2.0
"""Prior medians of the forcing spectrum's corner (Hz) and order."""


def _times(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` for real ``a`` ``(n, k)`` and complex ``b`` ``(k, ...)``: one real product over ``a``'s
    nonzero rows (``b``'s real and imaginary parts interleaved, no complex copy of ``a``), zero elsewhere."""
    b = np.ascontiguousarray(b)
    rows = np.flatnonzero(np.any(a != 0, axis=1))
    if rows.size == a.shape[0]:
        return (a @ b.reshape(b.shape[0], -1).view(np.float64)).view(complex).reshape((a.shape[0],) + b.shape[1:])
    out = np.zeros((a.shape[0],) + b.shape[1:], dtype=complex)
    if rows.size:
        prod = a[rows] @ b.reshape(b.shape[0], -1).view(np.float64)
        out[rows] = prod.view(complex).reshape((rows.size,) + b.shape[1:])
    return out


@dataclass(eq=False)
class BuffetingProblem:
    """Static mean and Whittle spectrum of a steady record (interface of :func:`levenberg_marquardt`).

    Parameters
    ----------
    steady : SteadyProblem
        The static problem (model, load shapes, sensor means, prior, full-order defect).
    spectra : SpectralData
        The record's binned cross-periodograms.
    aliases : int
        Aliased copies ``f + k fs``, ``|k| <= aliases``, in the sampled spectrum.
    log_a_ref : float
        Prior centre of ``log A`` (set by the start).
    """

    steady: SteadyProblem
    spectra: SpectralData
    aliases: int = 1
    log_a_ref: float = 0.0
    _cache: dict = field(default_factory=dict, repr=False)
    _weights: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        sp_ = self.steady
        if self.spectra.p != sp_.data.mean.size:
            raise InputError(f"buffeting: {self.spectra.p} spectral sensors for {sp_.data.mean.size} means")
        k = sp_.dim
        self.i_d, self.i_a, self.i_fc, self.i_n = k, k + 1, k + 2, k + 3
        self.i_sig = np.arange(k + 4, k + 4 + self.spectra.p)
        self.n_struct = k + 1  # load shapes, prestrains, damping: through the structure
        auto = np.real(np.einsum("bii->bi", self.spectra.periodogram))
        self.log_sigma_ref = 0.5 * np.log(np.maximum(np.quantile(auto, 0.2, axis=0), 1e-300) / self.spectra.dt)
        self.jacobian_defect = np.zeros((sp_.data.mean.size, sp_.modal.m))

    # -- layout ----------------------------------------------------------------------------
    @property
    def dim(self) -> int:
        return self.steady.dim + 4 + self.spectra.p

    @property
    def names(self) -> list[str]:
        sp_ = self.steady
        c = [f"c{i + 1}" for i in range(sp_.shapes.count)]
        sig = [f"log_sigma_{i + 1}" for i in range(self.spectra.p)]
        return c + list(sp_.pars) + ["log_damping", "log_A", "log_fc", "order"] + sig

    @cached_property
    def prior_matrix(self) -> np.ndarray:
        R = np.eye(self.dim)
        k = self.steady.dim
        R[:k, :k] = self.steady.prior_matrix
        return R

    def damping(self, theta: np.ndarray) -> float:
        m, s = self.steady.prior.mean_std("damping")
        return float(np.exp(m + s * theta[self.i_d]))

    def forcing(self, theta: np.ndarray) -> tuple[float, float, float]:
        """``(A, fc, n)`` of the forcing spectrum ``A (1 + (f/fc)^2)^-n`` (two-sided, 1/Hz)."""
        A = float(np.exp(self.log_a_ref + NUISANCE["log_A"] * theta[self.i_a]))
        fc = float(FC_REF * np.exp(NUISANCE["log_fc"] * theta[self.i_fc]))
        return A, fc, float(ORDER_REF * np.exp(NUISANCE["order"] * theta[self.i_n]))

    def noise(self, theta: np.ndarray) -> np.ndarray:
        """Noise std of each sensor."""
        return np.exp(self.log_sigma_ref + NUISANCE["log_sigma"] * theta[self.i_sig])

    @cached_property
    def omega(self) -> np.ndarray:
        """Angular frequencies ``(B, 2 aliases + 1)`` of the bins and their aliases."""
        ks = np.arange(-self.aliases, self.aliases + 1)
        return 2 * np.pi * (self.spectra.freq[:, None] + ks[None, :] / self.spectra.dt)

    @cached_property
    def filter_power(self) -> np.ndarray:
        """``|H(f + k fs)|^2`` ``(B, 2 aliases + 1)``: the acquisition's filter on each bin's aliases
        (ones for point sampling; zeros where a digital filter removes an alias)."""
        return self.spectra.acquisition.power(self.omega / (2 * np.pi), 1.0 / self.spectra.dt)

    @cached_property
    def noise_shape(self) -> np.ndarray:
        """The noise floor's shape ``(B,)``: white for point sampling (wideband noise folded back), the
        filter's aliased power otherwise (the sensors' noise comes before the filter)."""
        if self.spectra.acquisition.point:
            return np.ones(self.spectra.bins)
        return self.filter_power.sum(axis=1)

    # -- the structure ----------------------------------------------------------------------
    def structure(self, theta: np.ndarray, derivatives: bool = True) -> dict:
        """Static state, static outputs and the loaded modal matrices at ``theta``, with (``derivatives``)
        their derivatives along the ``n_struct`` structural unknowns."""
        sp_, fm = self.steady, self.steady.modal
        K, ne, P = sp_.shapes.count, len(sp_.pars), self.n_struct
        q, par = sp_.modal_state(theta[: sp_.dim])
        mat = sp_.model.problem.material
        ex, ey = par.eps0_x, par.eps0_y
        k0 = fm.omega(ex, ey) ** 2
        d = self.damping(theta)
        tx0, ty0 = fm.tensions(ex, ey)
        cb = mat.viscous / mat.areal_density + mat.kelvin_voigt * (tx0 * fm.kx + ty0 * fm.ky)
        r = fm.cubic_modes
        a = q[:r]
        # the cubic tensor is symmetric in all four indices: contracted once with a, it gives the secant
        # S(a) = a Ta and its derivative dS = 2 da Ta
        Ta = (a @ fm.tensor.reshape(r, -1)).reshape(r, r * r)
        Cq = fm.sensor_products(q[None])[0]  # (p, m)
        out = {
            "q": q,
            "s": np.einsum("pm,m->p", Cq, q) + sp_.defect,
            "J": 2.0 * Cq + self.jacobian_defect,
            "Kc": np.diag(k0[:r]) + 3.0 * (a @ Ta).reshape(r, r),
            "k0": k0,
            "c": d * cb,
            "u": sp_.forces @ theta[:K],
        }
        if not derivatives:
            return out
        C, nu = fm.stiffness_c, mat.poisson_ratio
        du = np.zeros((P, fm.m))
        dk0 = np.zeros((P, fm.m))
        dc = np.zeros((P, fm.m))
        du[:K] = sp_.forces.T
        for i, name in enumerate(sp_.pars):  # d/d prestrain of the tensions' stiffness and damping
            s = sp_.prior.mean_std(name)[1]
            gx, gy = (C, C * nu) if name == "prestrain_x" else (C * nu, C)
            dk0[K + i] = s * (gx * fm.kx + gy * fm.ky)
            dc[K + i] = d * mat.kelvin_voigt * dk0[K + i]
        dc[K + ne] = sp_.prior.mean_std("damping")[1] * d * cb
        # static sensitivities: F_q dq = du - dk0 q (implicit differentiation of the equilibrium)
        dq = fm.solve_tangent(q, par, (du - dk0 * q).T).T  # (P, m)
        dK = (6.0 * dq[:, :r] @ Ta).reshape(P, r, r)
        dK[:, np.arange(r), np.arange(r)] += dk0[:, :r]
        out.update(
            ds=2.0 * Cq @ dq.T,  # (p, P)
            dJ=2.0 * (fm.sensor_matrices.reshape(-1, fm.m) @ dq.T).reshape(-1, fm.m, P).transpose(2, 0, 1),
            dK=dK,
            dk0=dk0,
            dc=dc,
            du=du,
        )
        return out

    def transfer(self, st: dict, w: np.ndarray, derivatives: bool = True):
        """Transfer ``h`` ``(F, p)`` from the load factor to the sensors at angular frequencies ``w``
        ``(F,)``, and ``dh`` ``(P, F, p)`` along the structural unknowns."""
        r = self.steady.modal.cubic_modes
        Kc, cc, u, J = st["Kc"], st["c"][:r], st["u"], st["J"]
        # cubic block: G(w) = Vq diag(1/(i w - mu)) Wv from the state-space eigenpairs
        A = np.zeros((2 * r, 2 * r))
        A[:r, r:] = np.eye(r)
        A[r:, :r] = -Kc
        A[r:, r:] = -np.diag(cc)
        mu, V = sla.eig(A, check_finite=False)
        Wv = np.linalg.inv(V)[:, r:]
        Vq = V[:r]
        rho = 1.0 / (1j * w[:, None] - mu[None, :])  # (F, 2r)
        x = (rho * (Wv @ u[:r])) @ Vq.T  # G u (F, r)
        # linear modes beyond the block: uncoupled oscillators, frequency last (the products below are
        # real (rows, m - r) by complex (m - r, F): memory, not arithmetic, sets their cost)
        re, im = st["k0"][r:, None] - w[None, :] ** 2, w[None, :] * st["c"][r:, None]
        mag = re**2 + im**2
        gt = (re / mag) - 1j * (im / mag)  # (m - r, F)
        xlt = gt * u[r:, None]
        h = x @ J[:, :r].T + _times(J[:, r:], xlt).T
        if not derivatives:
            return h, None
        # dh = dJ x + lambda^T (du - dK x - i w dC x), lambda = G J^T (G symmetric)
        du, dK, dc, dJ, dk0 = st["du"], st["dK"], st["dc"], st["dJ"], st["dk0"]
        P, p, F = du.shape[0], J.shape[0], w.size
        lam = (Vq @ (rho.T[:, :, None] * (Wv @ J[:, :r].T)[:, None, :]).reshape(2 * r, -1)).reshape(r, F, p)
        xt = np.ascontiguousarray(x.T)  # (r, F)
        dh = _times(du[:, :r], lam) - (1j * w)[None, :, None] * _times(dc[:, :r], xt[:, :, None] * lam)
        Y = _times(np.ascontiguousarray(dK.transpose(0, 2, 1)).reshape(P * r, r), xt).reshape(P, r, F)  # dK x
        dh -= (Y.transpose(2, 0, 1) @ lam.transpose(1, 0, 2)).transpose(1, 0, 2)
        Jl = J[:, r:]

        def rows(a):  # (P p, m - r): a[P, j] J[k, j]
            return (a[:, None, :] * Jl[None]).reshape(P * p, -1)

        gxt = gt * xlt
        rest = _times(rows(du[:, r:]), gt) - _times(rows(dk0[:, r:]), gxt)
        rest -= (1j * w)[None, :] * _times(rows(dc[:, r:]), gxt)
        rest += _times(dJ.reshape(P * p, -1), np.concatenate([xt, xlt]))  # dJ x, both blocks
        dh += rest.reshape(P, p, F).transpose(0, 2, 1)
        return h, dh

    # -- the spectrum -----------------------------------------------------------------------
    def evaluate(self, theta: np.ndarray, derivatives: bool = False) -> dict:
        """Static outputs and model spectra ``S`` ``(B, p, p)`` at ``theta``; with ``derivatives`` also
        ``dS`` ``(dim, B, p, p)`` and ``ds`` (cached: the driver asks for the same point again after
        refreezing the weights; a trial step that is rejected never pays for its derivatives)."""
        key = theta.tobytes()
        hit = self._cache.get(key)
        if hit is not None and (not derivatives or "dS" in hit):
            return hit
        st = self.structure(theta, derivatives)
        B, p = self.spectra.bins, self.spectra.p
        w = self.omega.ravel()
        h, dh = self.transfer(st, w, derivatives)
        nk = self.omega.shape[1]
        h = h.reshape(B, nk, p)
        A, fc, n = self.forcing(theta)
        x = (w.reshape(B, nk) / (2 * np.pi * fc)) ** 2
        se = A * (1.0 + x) ** (-n) * self.filter_power  # the DAQ's filter on every alias
        hh = np.einsum("bk,bkp,bkq->bkpq", se, h, h.conj())
        signal = hh.sum(axis=1)
        sig = self.noise(theta)
        floor = self.spectra.dt * self.noise_shape[:, None] * sig[None, :] ** 2  # (B, p)
        S = signal + np.eye(p)[None] * floor[:, :, None]
        out = {"S": S, "s": st["s"], "structure": st}
        if derivatives:
            dh = dh.reshape(-1, B, nk, p)
            dS = np.zeros((self.dim, B, p, p), dtype=complex)
            cross = np.einsum("bk,abkp,bkq->abpq", se, dh, h.conj())
            dS[: self.n_struct] = cross + np.conj(np.swapaxes(cross, 2, 3))
            dS[self.i_a] = NUISANCE["log_A"] * signal
            dS[self.i_fc] = NUISANCE["log_fc"] * np.einsum("bk,bkpq->bpq", 2 * n * x / (1 + x), hh)
            dS[self.i_n] = -NUISANCE["order"] * n * np.einsum("bk,bkpq->bpq", np.log1p(x), hh)
            for i, j in enumerate(self.i_sig):
                dS[j, :, i, i] = 2 * NUISANCE["log_sigma"] * floor[:, i]
            ds = np.zeros((p, self.dim))
            ds[:, : self.n_struct] = st["ds"]
            out.update(dS=dS, ds=ds)
        if hit is None and len(self._cache) >= 4:
            self._cache.pop(next(iter(self._cache)))
        self._cache[key] = out
        return out

    def freeze(self, theta: np.ndarray) -> None:
        """Freeze the Whittle weights ``W_b = chol(S_b(theta))^-1``."""
        S = self.evaluate(np.asarray(theta, dtype=float))["S"]
        try:
            L = np.linalg.cholesky(S)
        except np.linalg.LinAlgError as exc:
            raise SolverError("buffeting fit", "model spectrum not positive definite", "check the data") from exc
        self._weights = np.linalg.inv(L)

    def whittle(self, theta: np.ndarray) -> float:
        """Whittle's negative log-likelihood ``sum_b n_b [log det S_b + tr(S_b^-1 Ī_b)]``."""
        S = self.evaluate(np.asarray(theta, dtype=float))["S"]
        L = np.linalg.cholesky(S)
        logdet = 2.0 * np.sum(np.log(np.real(np.einsum("bii->bi", L))), axis=1)
        tr = np.real(np.einsum("bii->b", np.linalg.solve(S, self.spectra.periodogram)))
        return float(self.spectra.weights @ (logdet + tr))

    def _vec(self, E: np.ndarray) -> np.ndarray:
        """Real rows of Hermitian matrices ``(..., p, p)``: diagonal, and sqrt2 (Re, Im) of the upper part."""
        p = E.shape[-1]
        iu = np.triu_indices(p, 1)
        dg = np.real(np.einsum("...ii->...i", E))
        up = E[..., iu[0], iu[1]]
        return np.concatenate([dg, np.sqrt(2) * up.real, np.sqrt(2) * up.imag], axis=-1)

    # -- the residual problem ---------------------------------------------------------------
    def residuals(self, theta: np.ndarray, jacobian: bool = False):
        """Data rows (static mean, then the frozen-weight Whittle rows) and prior rows; with
        ``jacobian`` their Jacobians (the weights must have been frozen)."""
        theta = np.asarray(theta, dtype=float)
        rp = self.prior_matrix @ theta
        if self._weights is None:
            raise SolverError("buffeting fit", "weights not frozen", "call freeze(theta) first")
        try:
            ev = self.evaluate(theta, jacobian)
        except (InputError, ArithmeticError, SolverError, np.linalg.LinAlgError) as exc:
            log.debug("buffeting trial rejected: %s", exc)
            rd = np.full(self.spectra.p + self.spectra.bins * self.spectra.p**2, np.inf)
            return (rd, rp) if not jacobian else (rd, rp, None, None)
        W, tau = self._weights, self.steady.tau
        sw = np.sqrt(self.spectra.weights)
        E = W @ (self.spectra.periodogram - ev["S"]) @ np.conj(np.swapaxes(W, 1, 2))
        rd = np.concatenate([(self.steady.data.mean - ev["s"]) / tau, (sw[:, None] * self._vec(E)).ravel()])
        if not jacobian:
            return rd, rp
        dE = W[None] @ ev["dS"] @ np.conj(np.swapaxes(W, 1, 2))[None]
        Jw = -(sw[None, :, None] * self._vec(dE)).reshape(self.dim, -1).T
        Jd = np.vstack([-ev["ds"] / tau[:, None], Jw])
        return rd, rp, Jd, self.prior_matrix
