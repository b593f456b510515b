"""The Gaussian side of the moving-horizon estimator: window prior, arrival cost, lift band.

:class:`WindowPrior` is held by :class:`~wingopt.estimation.mhe.estimator.MovingHorizonEstimator`
and owns the window's geometry (length, load blocks, basis) and its prior: the arrival cost in
information form, plus Tikhonov roughness, random-walk coupling and pressure bounds, assembled
into each window's problem. After each window the samples that leave it are absorbed into the
arrival cost (linearised at the window's optimum, Schur-complement marginalisation); the lift's
band is the Laplace posterior with lambda integrated out.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from wingopt.estimation.core.load_space import LoadSpace
from wingopt.estimation.mhe.load_model import RandomWalk, l2_metric
from wingopt.estimation.mhe.model import MHEModel
from wingopt.estimation.mhe.settings import MHESettings
from wingopt.estimation.mhe.window import LinearBounds, WindowProblem

__all__ = ["WindowPrior"]


def _marginalize(L: np.ndarray, eta: np.ndarray, keep: np.ndarray, drop: np.ndarray):
    """Gaussian marginalisation in information form (Schur complement)."""
    Lkk = L[np.ix_(keep, keep)]
    Lkd = L[np.ix_(keep, drop)]
    Ldd = L[np.ix_(drop, drop)]
    c = sla.cho_factor(0.5 * (Ldd + Ldd.T))
    X = sla.cho_solve(c, np.column_stack([Lkd.T, eta[drop]]))
    out = Lkk - Lkd @ X[:, :-1]
    return 0.5 * (out + out.T), eta[keep] - Lkd @ X[:, -1]


class WindowPrior:
    """Window geometry, arrival cost and lift band of one estimator run.

    Parameters
    ----------
    reduced : MHEModel
        The estimator's reduced model (at the data's sample time).
    load_space : LoadSpace
        The estimator's load space (the pressure bounds' points are evaluated in it).
    settings : MHESettings
        ``state_noise``, ``band_decades``, ``pressure_bounds``/``bound_grid`` and the random walk's
        ``load_timescale``/``shape_timescale`` are read.
    N, stride : int
        Window length and stride (samples).
    dt : float
        Sample time (s).
    blocks : int
        Load blocks of the random walk (1: a constant load over the window).
    Dx, Du : ndarray
        Scales of the modal state and of the modal forces (the unknowns are solved scaled).

    Notes
    -----
    The window starts with one load block: the start-up (scan, lambda path, onset) treats the first
    window's load as constant, and a random walk switches to its ``blocks`` afterwards
    (:meth:`to_random_walk`). The arrival cost is the weak prior on the initial state until
    :meth:`reset` is called; every window after the first one absorbs its predecessor (:meth:`absorb`).
    """

    def __init__(
        self,
        reduced: MHEModel,
        load_space: LoadSpace,
        settings: MHESettings,
        N: int,
        stride: int,
        dt: float,
        blocks: int,
        Dx: np.ndarray,
        Du: np.ndarray,
    ) -> None:
        self.reduced, self.settings = reduced, settings
        self.N, self.stride, self.dt, self.blocks = N, stride, dt, blocks
        self.Dx, self.Du = Dx, Du
        self.B = 1
        self.basis = reduced.window(N, 1)
        self.bounds_points = self._bound_rows(load_space) if settings.pressure_bounds else None
        self.rw: RandomWalk | None = None
        self._rw_metric = l2_metric(reduced) if blocks > 1 else None
        self.arrival: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def dim(self) -> int:
        """Number of unknowns of a window: initial modal state and ``B`` load blocks."""
        return (2 + self.B) * self.reduced.m

    @property
    def scale(self) -> np.ndarray:
        """Scale of every unknown (the solvers work on ``theta / scale``)."""
        return np.concatenate([self.Dx] + [self.Du] * self.B)

    def reset(self, x_prior: np.ndarray, rel: float) -> None:
        """Arrival cost of a first window: the prior on the initial modal state only.

        Std ``rel * A / omega_j`` (displacements) and ``rel * A`` (velocities) around ``x_prior``;
        information form over ``(x, u_1)`` in physical units.
        """
        m = self.reduced.m
        sx = rel * self.Dx
        Ia = np.zeros((3 * m, 3 * m))
        Ia[: 2 * m, : 2 * m] = np.diag(1.0 / sx**2)
        self.arrival = (Ia, np.concatenate([x_prior / sx**2, np.zeros(m)]))

    def to_random_walk(self, u: np.ndarray) -> None:
        """Switch from one load to the random walk's blocks, sized by the constant estimate ``u``."""
        s = self.settings
        self.rw = RandomWalk.build(self.reduced, s.load_timescale, s.shape_timescale, u, self._rw_metric)
        self.B = self.blocks
        self.basis = self.reduced.window(self.N, self.B)

    def absorb(self, problem: WindowProblem, theta: np.ndarray, shift: int) -> None:
        """Arrival cost for the window ``shift`` samples later (information form, stable).

        ``problem`` is the current window (with this arrival cost) and ``theta`` its optimum.
        """
        red, s = self.reduced, self.settings
        m = red.m
        Dx3 = self.scale[: 3 * m]
        # Data of the first `shift` samples depend on (x, u_1) only; linearise at the optimum.
        r, J = problem.linearize(theta)
        p = red.p
        Jh = J[: shift * p, : 3 * m] * Dx3[None, :]
        th = theta[: 3 * m] / Dx3
        Ia, ea = self.arrival
        Ia_s = Dx3[:, None] * Ia * Dx3[None, :]
        ea_s = Dx3 * ea
        L1 = Ia_s + Jh.T @ Jh
        e1 = ea_s + Jh.T @ (r[: shift * p] + Jh @ th)
        # Transition over `shift` steps in scaled coordinates, with process noise on the state.
        Fs, Gs = red.transition(shift)
        Dx, Du = self.Dx, self.Du
        Phi = np.zeros((2 * m, 2 * m))
        Phi[:m, :m] = np.diag(Fs[:, 0, 0])
        Phi[:m, m:] = np.diag(Fs[:, 0, 1])
        Phi[m:, :m] = np.diag(Fs[:, 1, 0])
        Phi[m:, m:] = np.diag(Fs[:, 1, 1])
        Gam = np.vstack([np.diag(Gs[:, 0]), np.diag(Gs[:, 1])])
        Phi_s = Phi * (Dx[None, :] / Dx[:, None])
        Gam_s = Gam * (Du[None, :] / Dx[:, None])
        Qi = np.eye(2 * m) / s.state_noise**2
        # Joint information over (x_old, u, x_new) with x_new = Phi x_old + Gam u + w.
        n3 = 5 * m
        Lj = np.zeros((n3, n3))
        ej = np.zeros(n3)
        Lj[: 3 * m, : 3 * m] = L1
        ej[: 3 * m] = e1
        Tm = np.hstack([Phi_s, Gam_s, -np.eye(2 * m)])
        Lj += Tm.T @ Qi @ Tm
        keep = np.r_[3 * m : 5 * m, 2 * m : 3 * m]  # (x_new, u)
        Lk, ek = _marginalize(Lj, ej, keep, np.arange(2 * m))
        if self.B > 1:
            # u_next = u + w_u, the random walk's increment over the `shift` samples between the old
            # and the new first block (the process noise of the load): marginalise the old block.
            Rs = self.rw.precision(shift * self.dt) * np.outer(Du, Du)
            Lr = np.zeros((4 * m, 4 * m))
            er = np.zeros(4 * m)
            Lr[: 3 * m, : 3 * m] = Lk
            er[: 3 * m] = ek
            Pm = np.hstack([np.zeros((m, 2 * m)), np.eye(m), -np.eye(m)])
            Lr += Pm.T @ Rs @ Pm
            Lk, ek = _marginalize(Lr, er, np.r_[: 2 * m, 3 * m : 4 * m], np.arange(2 * m, 3 * m))
        self.arrival = (Lk / np.outer(Dx3, Dx3), ek / Dx3)

    def lift_var(self, H: np.ndarray) -> np.ndarray:
        """Lift variance of every load block under the Gaussian with precision ``H`` (scaled solve)."""
        red, m, B = self.reduced, self.reduced.m, self.B
        D = self.scale
        Hs = D[:, None] * H * D[None, :]
        try:
            c = sla.cho_factor(0.5 * (Hs + Hs.T))
        except np.linalg.LinAlgError:
            return np.full(B, np.nan)
        out = np.empty(B)
        for b in range(B):
            rhs = np.zeros(self.dim)
            rhs[(2 + b) * m : (3 + b) * m] = red.lift_row * D[(2 + b) * m : (3 + b) * m]
            out[b] = rhs @ sla.cho_solve(c, rhs)
        return out

    def lift_band(self, H: np.ndarray, lam: float) -> np.ndarray:
        """1-sigma of the lift per load block: Laplace posterior, lambda integrated out.

        ``H`` is the Gauss–Newton precision at the window's optimum with the chosen ``lam``. The
        posterior depends on ``lambda``, which the data fix only to about a decade (the error curve
        is flat there); the band averages the posterior variance over a log-uniform ``lambda``
        within ``band_decades`` of the chosen one (9 points), the mean held at the estimate.
        ``band_decades = 0`` is the plain Laplace band at the chosen ``lambda``.
        """
        red, m, B = self.reduced, self.reduced.m, self.B
        decades = self.settings.band_decades
        xs = np.linspace(-decades, decades, 9) if decades > 0 else np.zeros(1)
        R = red.roughness
        variances = []
        for x in xs:
            Hx = H.copy()
            delta = lam * (10.0**x - 1.0)
            for b in range(B):
                sl = slice((2 + b) * m, (3 + b) * m)
                Hx[sl, sl] += delta * R
            variances.append(self.lift_var(Hx))
        return np.sqrt(np.maximum(np.nanmean(np.array(variances), axis=0), 0.0))

    def _bound_rows(self, load_space: LoadSpace) -> np.ndarray:
        """Rows mapping modal forces ``u`` to pressures at the bound points."""
        nx, ny = self.settings.bound_grid
        ls = load_space
        X, Y = np.meshgrid(np.linspace(0, ls.space.width, nx), np.linspace(0, ls.space.height, ny))
        E = ls.space.basis_matrix(X.ravel(), Y.ravel())
        return np.asarray(E @ self.reduced.load_map)

    def problem(self, y: np.ndarray, w: np.ndarray, start: int, lam: float) -> WindowProblem:
        """The window starting at sample ``start`` of the record ``(y, w)`` with the current arrival cost.

        Parameters
        ----------
        y, w : ndarray
            The whole record's outputs and weights (``1 / sigma^2``, 0 for a missing sample).
        start : int
            First sample of the window.
        lam : float
            Tikhonov weight of the load's roughness.

        Returns
        -------
        WindowProblem
        """
        red = self.reduced
        m, B, N = red.m, self.B, self.N
        dim = self.dim
        H0 = np.zeros((dim, dim))
        g0 = np.zeros(dim)
        Ia, ea = self.arrival
        k = Ia.shape[0]
        H0[:k, :k] += Ia
        g0[:k] += ea
        R = red.roughness
        for b in range(B):
            sl = slice((2 + b) * m, (3 + b) * m)
            H0[sl, sl] += lam * R
        if B > 1:
            # Random walk between consecutive blocks (stride samples apart).
            Q = self.rw.precision(self.stride * self.dt)
            for b in range(B - 1):
                i, j = slice((2 + b) * m, (3 + b) * m), slice((3 + b) * m, (4 + b) * m)
                H0[i, i] += Q
                H0[j, j] += Q
                H0[i, j] -= Q
                H0[j, i] -= Q
        bounds = None
        if self.bounds_points is not None:
            lo, hi = self.settings.pressure_bounds
            rows = []
            for b in range(B):
                A = np.zeros((self.bounds_points.shape[0], dim))
                A[:, (2 + b) * m : (3 + b) * m] = self.bounds_points
                rows.append(A)
            Ab = np.vstack(rows)
            bounds = LinearBounds(Ab, np.full(Ab.shape[0], lo), np.full(Ab.shape[0], hi))
        sl = slice(start, start + N)
        return WindowProblem(red, self.basis, y[sl], w[sl], 0.5 * (H0 + H0.T), g0, 0.0, self.scale, bounds)
