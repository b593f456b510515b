"""Rows of the streaming estimator: the model plug-in and the real-time-iteration normal equations.

The streaming estimator (:mod:`wingopt.estimation.streaming`) sees its model only through a
*row model*: an object that, sample by sample, hands out the data it needs to evaluate that
sample's sensor outputs later (``row_data()``), and evaluates the outputs and their Jacobian for
any set of rows at given parameters ``theta`` (``evaluate(theta, rows, columns)``). Everything else — the
rolling window, the arrival cost, the Gauss–Newton solve — is model-independent
(:class:`RtiNormalEquations`).

**Linear membrane** (:class:`LinearRows`): the dynamics are linear, so the modal displacement of
every sample is linear in the parameters ``theta = [q0, q0', u]`` (modal state at a fixed *origin*
sample, constant modal forces): ``q_k = a_k q0 + b_k q0' + c_k u`` per mode, with the per-mode
transition powers ``a_k, b_k, c_k`` advanced by one 2x2 step per sample (O(m) work, subnormals
flushed). Anchoring at the origin instead of at the window start makes the arrival cost exact
without any propagation or marginalisation: a row that leaves the window simply keeps its last
linearisation (its contribution to the normal equations is frozen). This is the batch MHE's
arrival cost with zero state process noise (the batch uses a relative 1e-6, "kept tiny").

**What a nonlinear model must provide** (e.g. a Berger-type membrane whose modes couple through
the stretch): the same three members (``dim``, ``p``, ``row_data``, ``evaluate``, ``lift_row``,
``load_slice``), but its state is not linear in ``(q0, q0', u)``, so it cannot be anchored at a
fixed origin for hours: ``evaluate`` integrates the window from a *window-start* state with
sensitivities, and the estimator then needs the batch's anchor shift (``shift(theta, s)``: the
state transition over ``s`` samples and its Jacobian, to propagate the arrival cost with a process
noise and marginalise the old state, as
:meth:`~wingopt.estimation.mhe.information.WindowPrior.absorb` does). That shift is not
implemented here (the linear model never needs it).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import blas

from wingopt.estimation.mhe.model import MHEModel, flush_subnormal

__all__ = ["LinearRows", "RtiNormalEquations", "DECAY_EXPONENT"]

DECAY_EXPONENT = 24.0
"""A mode's initial state is dropped once its free response is below ``e^-24 = 4e-11`` of its
size (times an oscillation factor of at most ~2 for the light damping here): far below the noise."""


class LinearRows:
    """Row model of the linear reduced membrane, parameters anchored at an origin sample.

    Parameters
    ----------
    reduced : MHEModel
        Modal model at the data's sample period.

    Attributes
    ----------
    dim : int
        ``3 m``: ``theta = [q0 (m), q0' (m), u (m)]`` in physical modal units.
    p : int
        Sensors.
    lift_row : ndarray ``(dim,)``
        ``lift = lift_row @ theta``.
    """

    def __init__(self, reduced: MHEModel) -> None:
        self.reduced = reduced
        m = reduced.m
        self.m, self.p, self.dim = m, reduced.p, 3 * m
        self.row_shape = (3, m)
        F = reduced.F
        self._F = (F[:, 0, 0].copy(), F[:, 0, 1].copy(), F[:, 1, 0].copy(), F[:, 1, 1].copy())
        self._g = reduced.g.copy()
        self._stack = np.ascontiguousarray(np.concatenate(list(reduced.sensor_matrices), axis=1))
        self.lift_row = np.concatenate([np.zeros(2 * m), reduced.lift_row])
        self.load_slice = slice(2 * m, 3 * m)
        self.restart()

    def decay_schedule(self, exponent: float = DECAY_EXPONENT) -> list[tuple[int, np.ndarray]]:
        """When the initial-state unknowns stop mattering: ``[(offset, indices into theta), ...]``.

        Mode ``j``'s free response decays like ``exp(-c_j t / 2)`` (relative to its load response in
        the scaled unknowns); after ``exponent / (c_j / 2)`` seconds it is below ``e^-exponent`` in
        every later row, and ``(q0_j, q0'_j)`` can be marginalised
        (:meth:`RtiNormalEquations.deactivate`). Sorted by offset (samples from the origin).
        """
        rate = 0.5 * self.reduced.damping
        out: dict[int, list[int]] = {}
        for j in range(self.m):
            if rate[j] > 0:
                k = int(np.ceil(exponent / (rate[j] * self.reduced.dt)))
                out.setdefault(k, []).extend([j, self.m + j])
        return [(k, np.array(sorted(v))) for k, v in sorted(out.items())]

    def restart(self) -> None:
        """Put the origin at the next sample (offset 0)."""
        m = self.m
        # Responses (displacement, velocity) per mode to a unit initial displacement, velocity, held force.
        self._pos = np.stack([np.ones(m), np.zeros(m), np.zeros(m)])
        self._vel = np.stack([np.zeros(m), np.ones(m), np.zeros(m)])

    def row_data(self) -> np.ndarray:
        """``[a_k, b_k, c_k]`` ``(3, m)`` of the next sample; advances the recursion by one sample."""
        out = self._pos.copy()
        f00, f01, f10, f11 = self._F
        pos, vel = self._pos, self._vel
        new_pos = f00 * pos + f01 * vel
        new_vel = f10 * pos + f11 * vel
        new_pos[2] += self._g[:, 0]
        new_vel[2] += self._g[:, 1]
        # Fast modes decay to subnormal numbers, which make every later product ~100x slower.
        self._pos, self._vel = flush_subnormal(new_pos), flush_subnormal(new_vel)
        return out

    def evaluate(
        self, theta: np.ndarray, rows: np.ndarray, columns: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Outputs ``(r, p)`` and Jacobian ``(r, p, dim)`` of rows ``(r, 3, m)`` at ``theta``.

        ``columns``: only these columns of the Jacobian (indices into ``theta``), in that order.
        """
        m, p = self.m, self.p
        th = theta.reshape(3, m)
        Q = (rows * th).sum(axis=1)
        CQ = (Q @ self._stack).reshape(-1, p, m)
        Y = (CQ @ Q[:, :, None])[:, :, 0]
        if columns is not None and columns.size == m and columns[0] == 2 * m:
            return Y, 2.0 * CQ * rows[:, None, 2, :]  # only the load's columns left (the usual case)
        J = (2.0 * CQ[:, :, None, :] * rows[:, None, :, :]).reshape(-1, p, 3 * m)
        return Y, (J if columns is None or columns.size == 3 * m else J[:, :, columns])


class RtiNormalEquations:
    """Gauss–Newton normal equations of a rolling window plus a frozen arrival part.

    Every row (sample) contributes ``J_k^T J_k`` and ``J_k^T z_k`` with ``z_k = r_k + J_k theta_k``
    (weighted, linearised at ``theta_k``). The sums ``H``, ``g`` hold the prior, every row that
    has left the window (frozen at its last linearisation: the arrival cost in information form)
    and the window's rows at their current linearisations. Re-linearising a row replaces its
    contribution (two rank-``p`` updates), so the Jacobian of the window is updated incrementally
    and a full re-linearisation of the window is spread over ``window / per_sample`` samples.

    Everything is in the scaled unknowns ``xi = theta / scale`` (all O(1)), and only the lower
    triangle of ``H`` is kept up to date (symmetric rank-``k`` updates, ``dsyrk``: half the work;
    the Cholesky factorisation reads the lower triangle only); :meth:`hessian` returns it whole.

    Parameters
    ----------
    model : row model (e.g. :class:`LinearRows`)
    window : int
        Rows kept (re-linearised); older rows are frozen into the arrival part.
    H0, g0 : ndarray
        Prior (quadratic part of the cost ``xi^T H0 xi - 2 g0^T xi``), scaled unknowns.
    scale : ndarray ``(dim,)``
        ``theta = scale * xi``.
    """

    def __init__(self, model, window: int, H0: np.ndarray, g0: np.ndarray, scale: np.ndarray) -> None:
        self.model = model
        self.scale = np.asarray(scale, dtype=float)
        self.window = int(window)
        p, dim = model.p, model.dim
        cap = self.window + 1
        self._cap = cap
        self.active = np.arange(dim)  # unknowns still estimated (see deactivate)
        self._rows = np.zeros((cap,) + tuple(model.row_shape))
        self._sw = np.zeros((cap, p))
        self._y = np.zeros((cap, p))
        self._J = np.zeros((cap, p, dim))
        self._z = np.zeros((cap, p))
        self._r2 = np.zeros(cap)
        self._n = np.zeros(cap, dtype=int)
        self._head = 0  # slot of the oldest row
        self._size = 0
        self._rr = 0  # round-robin position (relative to the oldest row)
        self.H = np.array(H0, dtype=float, order="F")
        self.g = np.array(g0, dtype=float)
        self._H0 = self.H.copy()  # prior + marginalised part, for the drift check only
        self._Hf = np.zeros(self.H.shape, order="F")  # frozen rows (lower triangle), for the drift check only
        self.chi2 = 0.0  # window misfit at the rows' linearisations
        self.n_data = 0
        self.absorbed = 0
        self.pushed = 0

    @property
    def size(self) -> int:
        return self._size

    @property
    def oldest_offset(self) -> int:
        """Sample offset (from the origin) of the oldest window row."""
        return self.pushed - self._size

    def hessian(self) -> np.ndarray:
        """``H`` with both triangles (the updates keep the lower one)."""
        L = np.tril(self.H)
        return L + np.tril(L, -1).T

    def _relinearize(self, theta: np.ndarray, slots: np.ndarray) -> None:
        a = self.active
        Y, J = self.model.evaluate(theta, self._rows[slots], a)
        D = self.scale[a]
        sw = self._sw[slots]
        Jw = J * (sw[:, :, None] * D)
        r = sw * (self._y[slots] - Y)
        z = r + Jw @ (theta[a] / D)
        nd = a.size
        Jo = self._J[slots, :, :nd].reshape(-1, nd)
        Jn = Jw.reshape(-1, nd)
        self.H = blas.dsyrk(1.0, Jn, beta=1.0, c=self.H, trans=1, lower=1, overwrite_c=1)
        self.H = blas.dsyrk(-1.0, Jo, beta=1.0, c=self.H, trans=1, lower=1, overwrite_c=1)
        self.g += Jn.T @ z.ravel() - Jo.T @ self._z[slots].ravel()
        r2 = (r * r).sum(axis=1)
        self.chi2 += float(r2.sum() - self._r2[slots].sum())
        self._J[slots, :, :nd] = Jw
        self._z[slots] = z
        self._r2[slots] = r2

    def push(self, theta: np.ndarray, y: np.ndarray, sw: np.ndarray, relinearize: int) -> None:
        """Add a sample (``y`` with NaN set to 0, ``sw = 1/sigma`` or 0 where missing) at ``theta``.

        The row leaving the window (if full) is re-linearised at ``theta`` and frozen; the new row
        and ``relinearize`` window rows (round robin) are linearised at ``theta``.
        """
        cap = self._cap
        new = (self._head + self._size) % cap
        self._rows[new] = self.model.row_data()
        self._y[new], self._sw[new] = y, sw
        self._J[new] = 0.0
        self._z[new] = 0.0
        self._r2[new] = 0.0
        self._n[new] = int(np.count_nonzero(sw))
        self.n_data += self._n[new]
        self._size += 1
        self.pushed += 1
        slots = [new]
        leaving = None
        if self._size > self.window:
            leaving = self._head
            slots.append(leaving)
        k = min(int(relinearize), self.window - 1)
        if k > 0 and self._size > 2:
            start = 1 if leaving is not None else 0
            span = self._size - 1 - start  # window rows other than the new one and the leaving one
            if span > 0:
                pos = (self._rr + np.arange(min(k, span))) % span
                self._rr = int((self._rr + k) % span)
                slots.extend(((self._head + start + pos) % cap).tolist())
        self._relinearize(theta, np.asarray(slots))
        if leaving is not None:
            # Frozen in H, g (arrival cost): only its misfit leaves the window's adequacy sum.
            nd = self.active.size
            self._Hf = blas.dsyrk(1.0, self._J[leaving, :, :nd], beta=1.0, c=self._Hf, trans=1, lower=1, overwrite_c=1)
            self.chi2 -= float(self._r2[leaving])
            self.n_data -= int(self._n[leaving])
            self._J[leaving] = 0.0
            self._z[leaving] = 0.0
            self._r2[leaving] = 0.0
            self._head = (self._head + 1) % cap
            self._size -= 1
            self.absorbed += 1

    def deactivate(self, drop: np.ndarray) -> None:
        """Marginalise the unknowns ``drop`` (indices into the full ``theta``) out of the equations.

        For unknowns that no future row depends on (the initial state of a mode whose transient
        has decayed below the rows' resolution): the Gaussian ``(H, g)`` is integrated over them
        (Schur complement), which leaves the estimate of the others unchanged, and the problem
        shrinks (the Cholesky factorisation per sample with it). Their columns in the window's
        stored Jacobians are dropped (they are below the decay threshold by construction).
        """
        drop = np.intersect1d(np.asarray(drop, dtype=int), self.active)
        if drop.size == 0:
            return
        pos = np.searchsorted(self.active, drop)
        keep = np.setdiff1d(np.arange(self.active.size), pos)
        H, g = self.hessian(), self.g
        Hdd = H[np.ix_(pos, pos)]
        X = np.linalg.solve(Hdd, np.column_stack([H[np.ix_(pos, keep)], g[pos]]))
        Hk = H[np.ix_(keep, keep)] - H[np.ix_(keep, pos)] @ X[:, :-1]
        self.H = np.asfortranarray(0.5 * (Hk + Hk.T))
        self.g = g[keep] - H[np.ix_(keep, pos)] @ X[:, -1]
        nd = self.active.size
        self._J[:, :, : keep.size] = self._J[:, :, :nd][:, :, keep]
        self._J[:, :, keep.size :] = 0.0
        self.active = self.active[keep]
        # The drift reference restarts from here: prior and frozen rows = H minus the window rows.
        slots = (self._head + np.arange(self._size)) % self._cap
        J = self._J[slots, :, : keep.size].reshape(-1, keep.size)
        self._H0 = self.H - J.T @ J
        self._Hf = np.zeros(self.H.shape, order="F")

    def relinearize_all(self, theta: np.ndarray) -> None:
        """Re-linearise every window row at ``theta`` (start-up only: not bounded per sample)."""
        if self._size:
            self._relinearize(theta, (self._head + np.arange(self._size)) % self._cap)

    def window_chi2_exact(self, theta: np.ndarray) -> float:
        """Window misfit at ``theta`` (all rows evaluated; a check, not for the per-sample path)."""
        slots = (self._head + np.arange(self._size)) % self._cap
        Y, _ = self.model.evaluate(theta, self._rows[slots])
        return float(np.sum((self._sw[slots] * (self._y[slots] - Y)) ** 2))

    def drift(self) -> float:
        """Relative difference between the incrementally updated ``H`` and a fresh sum (a check).

        ``H`` is updated by adding and subtracting rank-``p`` terms for hours; this compares it with
        the prior + the frozen rows + the window's rows summed afresh from the stored Jacobians.
        """
        slots = (self._head + np.arange(self._size)) % self._cap
        nd = self.active.size
        J = self._J[slots, :, :nd].reshape(-1, nd)
        Hf = np.tril(self._Hf)
        ref = self._H0 + Hf + np.tril(Hf, -1).T + J.T @ J
        return float(np.max(np.abs(self.hessian() - ref)) / np.max(np.abs(ref)))
