"""The Gaussian side of the moving-horizon estimator: window prior, arrival cost, lift band.

Mixed into :class:`~wingopt.estimation.mhe.estimator.MovingHorizonEstimator`. The window's prior
(arrival cost + Tikhonov roughness + random-walk coupling + pressure bounds) is assembled here;
after each window the samples that leave it are absorbed into the arrival cost in information
form (linearised at the window's optimum, Schur-complement marginalisation); the lift's band is
the Laplace posterior with lambda integrated out.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from wingopt.estimation.mhe.window import LinearBounds, WindowProblem

__all__ = ["WindowInformation"]


def _marginalize(L: np.ndarray, eta: np.ndarray, keep: np.ndarray, drop: np.ndarray):
    """Gaussian marginalisation in information form (Schur complement)."""
    Lkk = L[np.ix_(keep, keep)]
    Lkd = L[np.ix_(keep, drop)]
    Ldd = L[np.ix_(drop, drop)]
    c = sla.cho_factor(0.5 * (Ldd + Ldd.T))
    X = sla.cho_solve(c, np.column_stack([Lkd.T, eta[drop]]))
    out = Lkk - Lkd @ X[:, :-1]
    return 0.5 * (out + out.T), eta[keep] - Lkd @ X[:, -1]


class WindowInformation:
    """Window prior, arrival cost and lift band (mixin of the estimator)."""

    def _absorb(self, shift: int) -> None:
        """Arrival cost for the window ``shift`` samples later (information form, stable)."""
        red, s = self.reduced, self.settings
        m = red.m
        sol = self._sol
        problem = self._window_problem(self.start, self.lam)
        Dx3 = self.scale[: 3 * m]
        # Data of the first `shift` samples depend on (x, u_1) only; linearise at the optimum.
        r, J = problem.linearize(sol.theta)
        p = red.p
        Jh = J[: shift * p, : 3 * m] * Dx3[None, :]
        th = sol.theta[: 3 * m] / Dx3
        Ia, ea = self._arrival
        Ia_s = Dx3[:, None] * Ia * Dx3[None, :]
        ea_s = Dx3 * ea
        L1 = Ia_s + Jh.T @ Jh
        e1 = ea_s + Jh.T @ (r[: shift * p] + Jh @ th)
        # Transition over `shift` steps in scaled coordinates, with process noise on the state.
        Fs, Gs = red.transition(shift)
        Dx, Du = self._Dx, self._Du
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
            Rs = self._rw.precision(shift * self.dt) * np.outer(Du, Du)
            Lr = np.zeros((4 * m, 4 * m))
            er = np.zeros(4 * m)
            Lr[: 3 * m, : 3 * m] = Lk
            er[: 3 * m] = ek
            Pm = np.hstack([np.zeros((m, 2 * m)), np.eye(m), -np.eye(m)])
            Lr += Pm.T @ Rs @ Pm
            Lk, ek = _marginalize(Lr, er, np.r_[: 2 * m, 3 * m : 4 * m], np.arange(2 * m, 3 * m))
        self._arrival = (Lk / np.outer(Dx3, Dx3), ek / Dx3)
        self._shift = shift

    def _lift_var(self, H: np.ndarray) -> np.ndarray:
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

    def _lift_band(self, H: np.ndarray) -> np.ndarray:
        """1-sigma of the lift per load block: Laplace posterior, lambda integrated out.

        ``H`` is the Gauss–Newton precision at the window's optimum with the chosen ``lambda``. The
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
            delta = self.lam * (10.0**x - 1.0)
            for b in range(B):
                sl = slice((2 + b) * m, (3 + b) * m)
                Hx[sl, sl] += delta * R
            variances.append(self._lift_var(Hx))
        return np.sqrt(np.maximum(np.nanmean(np.array(variances), axis=0), 0.0))

    def _bound_rows(self) -> np.ndarray:
        """Rows mapping modal forces ``u`` to pressures at the bound points."""
        nx, ny = self.settings.bound_grid
        ls = self.load_space
        X, Y = np.meshgrid(np.linspace(0, ls.space.width, nx), np.linspace(0, ls.space.height, ny))
        E = ls.space.basis_matrix(X.ravel(), Y.ravel())
        return np.asarray(E @ self.reduced.load_map)

    @property
    def dim(self) -> int:
        return (2 + self.B) * self.reduced.m

    @property
    def scale(self) -> np.ndarray:
        return np.concatenate([self._Dx] + [self._Du] * self.B)

    def _window_problem(self, start: int, lam: float) -> WindowProblem:
        """The window starting at sample ``start`` with the current arrival cost."""
        red = self.reduced
        m, B, N = red.m, self.B, self.N
        dim = self.dim
        H0 = np.zeros((dim, dim))
        g0 = np.zeros(dim)
        Ia, ea = self._arrival
        k = Ia.shape[0]
        H0[:k, :k] += Ia
        g0[:k] += ea
        R = red.roughness
        for b in range(B):
            sl = slice((2 + b) * m, (3 + b) * m)
            H0[sl, sl] += lam * R
        if B > 1:
            # Random walk between consecutive blocks (stride samples apart).
            Q = self._rw.precision(self.stride * self.dt)
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
        return WindowProblem(red, self.basis, self.y[sl], self.w[sl], 0.5 * (H0 + H0.T), g0, 0.0, self.scale, bounds)
