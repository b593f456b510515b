"""Joint extended Kalman filter (JEKF): the seed's recursive load estimator (chapter 6, eqs. 6.15–6.46).

The method (joint state, transition, process noise, Joseph form, regularised prior) is summarised
in :mod:`wingopt.estimation.jekf`.

**Structure used for speed (exact).** The membrane's damping is Rayleigh, so with M-orthonormal
modes ``z = Phi q`` and the modal load ``g = Phi^T M f`` (``f = rho h Phi g``) the joint system
splits into one 3x3 block ``[q_k, q_k', g_k]`` per mode. The joint state is stored interleaved per
mode, so the transition is block diagonal and ``F P F^T`` costs ``O(n^2)`` (two batched 3x3
products) instead of the ``O(n^3)`` dense product; the measurement update is rank ``p`` (4
sensors) and is applied as one rank-``2p`` BLAS update of ``P``. Both are exact re-arrangements:
the Kalman filter is invariant under the linear change of coordinates, and keeping all modes
(``modes=None``, the default) is the full model. ``structure="dense"`` runs the same filter in
physical coordinates with the dense joint transition (the reference, ~``(3n)^3`` work per step).

**Sign.** Stretch sensors are sign-blind: the data are unchanged when the initial state and the
load both flip sign. The filter linearises about its current state, so the sign of the estimate
follows the prior initial deflection, the bubble ``initial_peak * 16 xi (1 - xi) eta (1 - eta)``
(the problem's ``initial_deflection``; when unknown, 1 cm with the sign of ``initial_load``).

Use :func:`jekf_identify` for a one-shot run, or the step-able :class:`JointEKF`
(``setup`` / ``step`` / ``run``). The two ways of choosing ``lambda`` are in
:mod:`wingopt.estimation.jekf.tuning`.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np
from scipy.linalg.blas import dgemm
from scipy.linalg.lapack import dpotrf as _potrf
from scipy.linalg.lapack import dpotrs as _potrs

from wingopt.dynamics import zoh
from wingopt.errors import InputError, SolverError
from wingopt.estimation.declaration import with_declaration
from wingopt.estimation.jekf.batch import WholeRecord
from wingopt.estimation.jekf.prior import JointPrior
from wingopt.estimation.jekf.settings import JEKFSettings, _as_positive
from wingopt.estimation.jekf.transition import _first_order, _joint, _modal_blocks, joint_transition
from wingopt.membrane.model import MembraneModel

__all__ = ["JEKFSettings", "JointEKF", "joint_transition"]

log = logging.getLogger(__name__)


class JointEKF(WholeRecord):
    """Step-able joint EKF on the membrane (``setup`` / ``step``; ``run``: a whole record,
    :class:`~wingopt.estimation.jekf.batch.WholeRecord`).

    Parameters
    ----------
    model : MembraneModel
        The estimator's model (its mesh is the estimator's mesh).
    settings : JEKFSettings, optional
        Default: the seed-faithful :meth:`JEKFSettings.seed` with ``lambda = 1``; its
        ``declaration`` is filled from the model's problem when ``None``.
    dt : float, optional
        Default sample period (s) for :meth:`step` without a time; default the declared ``dt``.

    Examples
    --------
    >>> ekf = JointEKF(model, JEKFSettings.tuned(regularization=1e-9))   # doctest: +SKIP
    >>> result = ekf.run(measurements)                                  # doctest: +SKIP
    >>> ekf.setup(measurement_variance=sigma**2); ekf.step(y0, t=0.0); ekf.step(y1)  # doctest: +SKIP
    """

    def __init__(self, model: MembraneModel, settings: JEKFSettings | None = None, dt: float | None = None) -> None:
        if not isinstance(model, MembraneModel):
            raise InputError(f"model: expected a MembraneModel, got {type(model).__name__}")
        self.model = model
        settings = JEKFSettings.seed() if settings is None else settings
        if not isinstance(settings, JEKFSettings):
            raise InputError(f"settings: expected JEKFSettings, got {type(settings).__name__}")
        self.settings = with_declaration(settings, model.problem)
        self.dt = float(self.settings.declaration.dt if dt is None else dt)
        _as_positive("dt", self.dt)
        self.n = model.n
        self.prior = JointPrior(model, self.settings)  # initial covariance and guess
        self.sensors = model.sensors
        self.p = len(self.sensors)
        s = self.settings
        t0 = time.perf_counter()
        if s.structure == "modal":
            modal = model.modal(None if s.modes is None else min(int(s.modes), self.n))
            self.r = modal.count
            self._phi = modal.shapes  # (n, r), mass-orthonormal
            self._modal = modal
            self._areal = model.problem.material.areal_density
            # q = Phi^T (rho h M) z ;  g = Phi^T M f ;  f = rho h Phi g
            self._to_q = np.asarray((model.mass @ self._phi).T)
            self._to_g = np.asarray((model.gram @ self._phi).T)
            # The sensors in modal coordinates: s_i = z^T C_i z = q^T G_i q with G_i = Phi^T C_i Phi
            # (r x r, symmetric): h and its Jacobian 2 G_i q per sample without the n-sized products.
            G = np.stack([np.asarray(self._phi.T @ (C @ self._phi)) for C in self.sensors.matrices])
            self._G = 0.5 * (G + G.transpose(0, 2, 1))
            self.size = 3 * self.r
            self._qidx = slice(0, self.size, 3)
            self._vidx = slice(1, self.size, 3)
            self._gidx = slice(2, self.size, 3)
        else:
            self.r = self.n
            self.size = 3 * self.n
            self._first_order = _first_order(model)
            self._qidx = slice(0, self.n)
            self._vidx = slice(self.n, 2 * self.n)
            self._gidx = slice(2 * self.n, 3 * self.n)
        self._transitions: dict[float, np.ndarray] = {}
        self._lift_weights = self._load_weights(model.basis_integrals)
        self.build_seconds = time.perf_counter() - t0
        self._ready = False

    # -- coordinates -----------------------------------------------------------------------
    def _load_weights(self, a: np.ndarray) -> np.ndarray:
        """Vector ``w`` on the load entries of the state with ``a^T f = w^T s_load``."""
        if self.settings.structure == "modal":
            return self._areal * (self._phi.T @ a)
        return np.asarray(a, dtype=float)

    def _state_from_physical(self, z: np.ndarray, v: np.ndarray, f: np.ndarray) -> np.ndarray:
        x = np.empty(self.size)
        if self.settings.structure == "modal":
            x[self._qidx], x[self._vidx], x[self._gidx] = self._to_q @ z, self._to_q @ v, self._to_g @ f
        else:
            x[self._qidx], x[self._vidx], x[self._gidx] = z, v, f
        return x

    def _deflection(self, x: np.ndarray) -> np.ndarray:
        return self._phi @ x[self._qidx] if self.settings.structure == "modal" else x[self._qidx].copy()

    def _velocity(self, x: np.ndarray) -> np.ndarray:
        return self._phi @ x[self._vidx] if self.settings.structure == "modal" else x[self._vidx].copy()

    def _load(self, x: np.ndarray) -> np.ndarray:
        if self.settings.structure == "modal":
            return self._areal * (self._phi @ x[self._gidx])
        return x[self._gidx].copy()

    def _histories(self, states: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Loads ``(N, n)``, deflections ``(N, n)`` and lifts ``(N,)`` of a history of joint states
        ``(N, size)``: one matrix product each after a run instead of two mode-to-node products per sample."""
        g, q = states[:, self._gidx], states[:, self._qidx]
        lift = g @ self._lift_weights
        if self.settings.structure == "modal":
            return self._areal * (g @ self._phi.T), q @ self._phi.T, lift
        return g.copy(), q.copy(), lift

    def _block_covariance(self, cov_z: np.ndarray, cov_v: np.ndarray, cov_f: np.ndarray) -> np.ndarray:
        """Block-diagonal prior in filter coordinates from physical blocks."""
        P = np.zeros((self.size, self.size))
        if self.settings.structure == "modal":
            tq, tg = self._to_q, self._to_g
            blocks = ((self._qidx, tq @ cov_z @ tq.T), (self._vidx, tq @ cov_v @ tq.T), (self._gidx, tg @ cov_f @ tg.T))
        else:
            blocks = ((self._qidx, cov_z), (self._vidx, cov_v), (self._gidx, cov_f))
        for idx, block in blocks:
            P[idx, idx] = 0.5 * (block + block.T)
        return P

    def transition(self, dt: float) -> np.ndarray:
        """Joint transition for a step of ``dt``: ``(r, 3, 3)`` per-mode blocks, or dense ``(3n, 3n)``."""
        key = round(float(dt), 12)
        tr = self._transitions.get(key)
        if tr is None:
            if self.settings.structure == "modal":
                tr = _modal_blocks(self._modal, dt)
            else:
                tr = _joint(*zoh(*self._first_order, dt))
            if len(self._transitions) > 64:  # irregular sampling: do not grow without bound
                self._transitions.clear()
            self._transitions[key] = tr
        return tr

    def _process_noise(self, dt: float) -> np.ndarray | None:
        """Load-block process noise over ``dt`` (Gelb: ``Qd dt`` per coefficient), filter coordinates."""
        q = self.settings.process_intensity
        if q == 0.0:
            return None
        if self.settings.structure == "modal":
            return q * dt * (self._to_g @ self._to_g.T)
        return q * dt * np.eye(self.n)

    def setup(
        self,
        initial_deflection: np.ndarray | None = None,
        initial_velocity: np.ndarray | None = None,
        initial_load: np.ndarray | None = None,
        measurement_variance: float | np.ndarray | None = None,
        t0: float = 0.0,
    ) -> JointEKF:
        """Initialise mean and covariance at time ``t0`` (defaults from ``prior.initial_guess()``).

        ``measurement_variance`` overrides the settings' ``R`` (needed when the settings say
        ``None``, i.e. "from the data": :meth:`run` fills it from the measurements).
        """
        z0, v0, f0 = self.prior.initial_guess()
        z0 = z0 if initial_deflection is None else self._vector("initial_deflection", initial_deflection)
        v0 = v0 if initial_velocity is None else self._vector("initial_velocity", initial_velocity)
        f0 = f0 if initial_load is None else self._vector("initial_load", initial_load)
        R = self.settings.measurement_variance if measurement_variance is None else measurement_variance
        if R is None:
            raise InputError(
                "measurement_variance = None: the settings take R from the data; pass measurement_variance "
                "to setup() or use run(measurements)"
            )
        R = np.broadcast_to(np.asarray(R, dtype=float), (self.p,)).copy() if np.ndim(R) <= 1 else None
        if R is None or not np.all(np.isfinite(R) & (R > 0)):
            raise InputError(f"measurement_variance: expected {self.p} positive variances (or one)")
        self.R = R
        s = self.settings
        eye = np.eye(self.n)
        self.x = self._state_from_physical(z0, v0, f0)
        self.P = np.ascontiguousarray(
            self._block_covariance(
                s.deflection_std**2 * eye, s.velocity_std**2 * eye, self.prior.prior_load_covariance()
            )
        )
        self._work = (np.empty_like(self.P), np.empty_like(self.P))
        self.t = float(t0)
        self._started = False
        self._steps = 0
        self._updates = 0
        self._skipped = 0
        self.loglik = 0.0
        self.nis_sum = 0.0
        self.innovation_count = 0
        self.last_nis = float("nan")
        self.last_innovation = np.full(self.p, np.nan)
        self._ready = True
        return self

    def _vector(self, name: str, v) -> np.ndarray:
        arr = np.asarray(v, dtype=float)
        if arr.shape != (self.n,) or not np.all(np.isfinite(arr)):
            raise InputError(f"{name}: shape {arr.shape}, expected ({self.n},) finite coefficients")
        return arr

    # -- the filter ----------------------------------------------------------------------------
    def predict(self, dt: float) -> None:
        """Time update over ``dt``: ``x <- F x``, ``P <- F P F^T + Q`` (exact block-diagonal form)."""
        if dt <= 0:
            return
        tr = self.transition(dt)
        x, P = self.x, self.P
        if self.settings.structure == "modal":
            r = self.r
            self.x = np.matmul(tr, x.reshape(r, 3, 1)).reshape(-1)
            # F P F^T with F block-diagonal (3x3 per mode) = F (F P)^T for symmetric P: two batched
            # row operations. Only the q, q' rows change (the load rows of F are [0, 0, 1]).
            rows = np.ascontiguousarray(tr[:, :2, :])
            P3, A, B = P.reshape(r, 3, -1), self._work[0], self._work[1]
            A3 = A.reshape(r, 3, -1)
            A3[:, 2, :] = P3[:, 2, :]
            np.matmul(rows, P3, out=A3[:, :2, :])
            np.copyto(B, A.T)
            B3 = B.reshape(r, 3, -1)
            P3[:, 2, :] = B3[:, 2, :]
            np.matmul(rows, B3, out=P3[:, :2, :])
        else:
            self.x = tr @ x
            self.P = tr @ P @ tr.T
        Q = self._process_noise(dt)
        if Q is not None:
            self.P[self._gidx, self._gidx] += Q
        self.t += dt

    def update(self, y: np.ndarray) -> bool:
        """Measurement update with the finite entries of ``y`` (Joseph form); ``False`` if none."""
        y = np.asarray(y, dtype=float)
        if y.shape != (self.p,):
            raise InputError(f"y: shape {y.shape}, expected ({self.p},) sensor values")
        ok = np.isfinite(y)
        if not ok.any():
            self._skipped += 1
            self.last_nis = float("nan")
            self.last_innovation = np.full(self.p, np.nan)
            return False
        if self.settings.structure == "modal":
            q = self.x[self._qidx]
            Gq = (self._G if ok.all() else self._G[ok]) @ q  # (m, r)
            h = Gq @ q
            Hq = 2.0 * Gq  # (m, r)
        else:
            z = self._deflection(self.x)
            mats = [C for C, use in zip(self.sensors.matrices, ok) if use]
            Cz = np.stack([C @ z for C in mats])  # (m, n)
            h = Cz @ z
            Hq = 2.0 * Cz
        P = self.P
        # U = P H^T with H non-zero on the deflection entries only; P symmetric -> U^T = Hq P[q, :]
        U = np.ascontiguousarray((Hq @ P[self._qidx, :]).T)  # (N, m)
        S = Hq @ U[self._qidx, :]
        S = 0.5 * (S + S.T) + np.diag(self.R[ok])
        # LAPACK's potrf/potrs directly: the same arithmetic as scipy's cho_factor/cho_solve, without
        # their argument checks, which cost more than the 4x4 factorisation itself at every sample.
        m, N = S.shape[0], U.shape[0]
        cS, info = _potrf(S, lower=1, clean=0)
        if info != 0:
            raise SolverError("jekf", "innovation covariance not positive definite", "check R > 0")
        # S is only m x m (m <= p sensors): invert it and multiply, rather than a triangular solve
        # with N right-hand sides (a threaded BLAS call that stalls on a busy machine).
        Sinv, info = _potrs(cS, np.eye(m), lower=1)
        Sinv = 0.5 * (Sinv + Sinv.T)
        K = U @ Sinv  # (N, m)
        e = y[ok] - h
        if ok.all():
            self.last_innovation = e
        else:
            self.last_innovation = np.full(self.p, np.nan)
            self.last_innovation[ok] = e
        # Innovation statistics (prediction-error decomposition of the likelihood): lambda rules.
        nis = float(e @ Sinv @ e)
        logdet = 2.0 * float(np.log(cS.diagonal()).sum())
        self.last_nis = nis
        self.nis_sum += nis
        self.innovation_count += int(ok.sum())
        self.loglik += -0.5 * (nis + logdet + ok.sum() * math.log(2 * math.pi))
        self.x = self.x + K @ e
        # Joseph form (I - K H) P (I - K H)^T + K R K^T, expanded exactly as
        # P - K U^T - U K^T + K S K^T  =  P - [K, U] [U - K S, K]^T : one rank-2m BLAS update in place.
        W, V = np.empty((N, 2 * m), order="F"), np.empty((N, 2 * m), order="F")  # filled in place: no hstack copies
        W[:, :m], W[:, m:] = K, U
        np.subtract(U, K @ S, out=V[:, :m])
        V[:, m:] = K
        # P is C-ordered and symmetric: update its transpose (Fortran view) in place, P^T -= V W^T.
        PT = dgemm(-1.0, V, W, beta=1.0, c=P.T, trans_b=True, overwrite_c=True)
        if not np.shares_memory(PT, P):  # pragma: no cover - BLAS wrapper copied; keep correctness
            self.P = np.ascontiguousarray(PT.T)
        self._updates += 1
        return True

    def _symmetrize(self) -> None:
        # Round-off only: the updates are symmetric in exact arithmetic.
        work = self._work[0]
        np.add(self.P, self.P.T, out=work)
        np.multiply(work, 0.5, out=self.P)

    def step(self, y: np.ndarray, t: float | None = None) -> np.ndarray:
        """Advance to the sample time ``t`` (default: one ``dt`` later; the first call uses ``t0``),
        then update with ``y`` (NaN entries are skipped; an all-NaN sample is prediction only).

        Returns the posterior load coefficients (deflection basis).
        """
        if not self._ready:
            self.setup()
        if t is None:
            dt = self.dt if self._started else 0.0
        else:
            dt = float(t) - self.t
            if dt < -1e-12 * max(1.0, abs(self.t)):
                raise InputError(f"t = {t!r}: earlier than the filter's time {self.t!r}")
        self.predict(dt)
        self._started = True
        self.update(y)
        self._steps += 1
        if self._steps % self.settings.symmetrize_every == 0:
            self._symmetrize()
        return self.load

    # -- current estimate ----------------------------------------------------------------------
    @property
    def load(self) -> np.ndarray:
        """Posterior load coefficients ``f`` (deflection basis, ``P ≈ Σ f_i phi_i``)."""
        return self._load(self.x)

    @property
    def deflection(self) -> np.ndarray:
        return self._deflection(self.x)

    @property
    def velocity(self) -> np.ndarray:
        return self._velocity(self.x)

    @property
    def lift(self) -> float:
        """``∫ P_hat`` (N)."""
        return float(self._lift_weights @ self.x[self._gidx])

    @property
    def lift_std(self) -> float:
        """1-sigma of the lift from the load block of ``P``: ``sqrt(a^T P_ff a)``."""
        w = self._lift_weights
        return float(np.sqrt(max(w @ (self.P[self._gidx, self._gidx] @ w), 0.0)))

    def load_covariance(self) -> np.ndarray:
        """Posterior covariance of the load coefficients ``f`` (dense ``(n, n)``)."""
        Pg = self.P[self._gidx, self._gidx]
        if self.settings.structure == "modal":
            T = self._areal * self._phi
            return T @ Pg @ T.T
        return Pg.copy()
