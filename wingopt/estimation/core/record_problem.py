"""The least-squares problem of one record: unknowns, priors, residuals and the exact Jacobian.

Unknowns (scaled so that every Gaussian prior is ``N(0, 1)`` in them): the initial modal state
``[q0, q0']`` (prior mean: the problem's initial bubble, std ``A omega_1/omega_j`` and
``A omega_1``), the load-shape coefficients ``c`` (smoothness prior of
:class:`~wingopt.estimation.core.load_model.LoadShapes`), the gust amplitude knots ``g``
(optional, :class:`~wingopt.estimation.core.load_model.GustAmplitude`) and the free model
parameters (prestrains with a relative prior, the damping factor with a log-normal prior).

The cost ``|r|^2`` is a chi-square: data rows ``(y - s(theta)) / sigma`` for the samples present
(a missing sample is a missing row, never invented) and the prior rows. The Jacobian is exact:
the whole batch of complex-step perturbations is integrated at once
(the modal models' ``simulate`` is analytic in all its
arguments), and ``ds/dtheta = 2 (C q)^T dq/dtheta``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.core.load_model import GustAmplitude, LoadShapes
from wingopt.estimation.declaration import declaration_of
from wingopt.measurements.acquisition import SampleFilter
from wingopt.measurements.analog_filter import CausalFilter
from wingopt.measurements.decimation_filter import DecimationFilter
from wingopt.membrane.forward import ForceTangent, ModalMembrane
from wingopt.problem.membrane import IdentificationSettings

__all__ = ["PARAMETERS", "ParameterPrior", "RecordProblem"]

PARAMETERS = ("prestrain_x", "prestrain_y", "damping")
"""Names of the identifiable model parameters (``damping``: a factor on gamma and eta)."""

_H = 1e-30
"""Complex-step size (scaled units): exact derivatives, no cancellation."""


@dataclass(frozen=True)
class ParameterPrior:
    """Prior of the model parameters: means and which are free.

    ``prestrain_rel``: relative std of each prestrain, or ``prestrain_std`` their absolute stds and
    ``correlation`` (a calibration's posterior); ``damping_rel``: the damping factor's prior is
    log-normal with std ``log(1 + damping_rel)``.
    """

    prestrain: tuple[float, float]
    free: tuple[str, ...] = PARAMETERS
    prestrain_rel: float = 0.2
    damping: float = 1.0
    damping_rel: float = 1.0
    prestrain_std: tuple[float, float] | None = None
    correlation: float = 0.0

    @classmethod
    def from_problem(
        cls, problem, free=None, prestrain_rel=None, damping_rel=None, declaration: IdentificationSettings | None = None
    ) -> ParameterPrior:
        """The problem file's prior (a calibration's posterior when it carries one); arguments override.

        ``declaration``: the ``[identification]`` the fit runs with (its settings' ``declaration``);
        ``None``: the problem's own (:func:`~wingopt.estimation.declaration.declaration_of`).
        """
        ident = declaration_of(problem) if declaration is None else declaration
        e0 = problem.material.prestrain
        mean = ident.prestrain if ident.prestrain is not None else (e0, e0)
        rel = ident.prestrain_prior_rel if prestrain_rel is None else prestrain_rel
        std = ident.prestrain_std if prestrain_rel is None else None
        if damping_rel is None:
            damping_rel = ident.damping_prior_rel if ident.damping_std is None else ident.damping_std / ident.damping
        free = ident.free_parameters if free is None else free
        corr = ident.prestrain_correlation if std is not None else 0.0
        return cls(tuple(mean), tuple(free), rel, ident.damping, damping_rel, None if std is None else tuple(std), corr)

    def __post_init__(self) -> None:
        bad = [n for n in self.free if n not in PARAMETERS]
        if bad:
            names = ", ".join(PARAMETERS)
            raise InputError(f"free_parameters: {bad[0]!r} is not a parameter; expected some of {names}")
        for name in ("prestrain_rel", "damping_rel", "damping"):
            val = getattr(self, name)
            if not (np.isfinite(val) and val > 0):
                raise InputError(f"{name} = {val!r}: expected a positive number")

    def mean_std(self, name: str) -> tuple[float, float]:
        """Prior mean and std in the unknown's own units (log for the damping)."""
        if name == "damping":
            return float(np.log(self.damping)), float(np.log1p(self.damping_rel))
        i = 0 if name == "prestrain_x" else 1
        e = self.prestrain[i]
        return float(e), float(self.prestrain_rel * e if self.prestrain_std is None else self.prestrain_std[i])


@dataclass(frozen=True, eq=False)
class RecordProblem:
    """One record's estimation problem for a modal membrane (Berger or cubic FvK)."""

    model: ModalMembrane
    shapes: LoadShapes
    t: np.ndarray
    y: np.ndarray
    sigma: np.ndarray
    prior: ParameterPrior
    x0_mean: np.ndarray
    x0_std: np.ndarray
    gust: GustAmplitude | None = None
    nonlinear: bool = True
    state_modes: int | None = None
    jacobian: str = "tangent"
    daq: SampleFilter | CausalFilter | DecimationFilter | None = None
    """The DAQ's filter: a declared analog one run causally on the outputs' Hermite interpolant at
    the integrator's sub-steps (:class:`~wingopt.measurements.analog_filter.CausalFilter`, the modal
    velocities giving the slopes), or as it acts on the samples
    (:meth:`~wingopt.measurements.acquisition.Acquisition.sample_filter`); the predicted outputs pass
    through it as the record did; ``None``: point sampling."""

    def __post_init__(self) -> None:
        ms = self.model.m if self.state_modes is None else int(self.state_modes)
        if not 1 <= ms <= self.model.m:
            raise InputError(f"state modes = {ms}: expected 1..{self.model.m}")
        object.__setattr__(self, "state_modes", ms)
        if self.jacobian not in ("tangent", "complex-step"):
            raise InputError(f"jacobian = {self.jacobian!r}: expected 'tangent' or 'complex-step'")
        if self.y.shape != (self.t.size, self.model.p):
            raise InputError(f"measurements: shape {self.y.shape}, expected ({self.t.size}, {self.model.p})")
        if self.t.size < 2:
            raise InputError("measurements: need at least 2 samples")

    # -- layout ----------------------------------------------------------------------------
    @cached_property
    def hats(self) -> np.ndarray | None:
        return None if self.gust is None else self.gust.basis(self.t)

    @property
    def sizes(self) -> tuple[int, int, int, int]:
        """``(2m, n_shapes, n_knots, n_params)``."""
        ng = 0 if self.hats is None else self.hats.shape[1]
        return 2 * self.state_modes, self.shapes.count, ng, len(self.prior.free)

    @property
    def dim(self) -> int:
        return sum(self.sizes)

    @cached_property
    def slices(self) -> dict[str, slice]:
        out, start = {}, 0
        for name, size in zip(("x0", "c", "g", "par"), self.sizes):
            out[name] = slice(start, start + size)
            start += size
        return out

    @cached_property
    def _par_mean_std(self) -> tuple[np.ndarray, np.ndarray]:
        ms = [self.prior.mean_std(n) for n in self.prior.free]
        return np.array([a for a, _ in ms]), np.array([b for _, b in ms])

    @cached_property
    def _force_shapes(self) -> np.ndarray:
        """Modal forces of the load shapes ``(n_shapes, m)``."""
        return self.shapes.modal_forces(self.model.shapes)

    @cached_property
    def valid(self) -> np.ndarray:
        return np.isfinite(self.y)

    @property
    def n_data(self) -> int:
        return int(self.valid.sum())

    # -- unknowns to physics ---------------------------------------------------------------
    def physical(self, theta: np.ndarray) -> dict:
        """Physical unknowns of ``theta`` ``(dim,)`` or a batch ``(B, dim)`` (complex allowed)."""
        th = np.atleast_2d(theta)
        sl, md, ms = self.slices, self.model.m, self.state_modes
        x0 = np.tile(self.x0_mean.astype(th.dtype), (th.shape[0], 1))
        xs = th[:, sl["x0"]]
        x0[:, :ms] += self.x0_std[:ms] * xs[:, :ms]
        x0[:, md : md + ms] += self.x0_std[md : md + ms] * xs[:, ms:]
        c = self.shapes.prior_std * th[:, sl["c"]]
        g = th[:, sl["g"]]
        pm, ps = self._par_mean_std
        par = pm + ps * th[:, sl["par"]]
        vals = {}
        for name in PARAMETERS:
            if name in self.prior.free:
                v = par[:, self.prior.free.index(name)]
                vals[name] = np.exp(v) if name == "damping" else v
            else:
                mean = self.prior.mean_std(name)[0]
                vals[name] = np.full(th.shape[0], np.exp(mean) if name == "damping" else mean)
        return {"q0": x0[:, :md], "v0": x0[:, md:], "c": c, "g": g, **vals}

    def amplitude(self, g: np.ndarray) -> np.ndarray:
        """``1 + g(t_k)`` ``(N, B)`` for knot values ``g`` ``(B, n_knots)``."""
        if self.hats is None:
            return np.ones((self.t.size, g.shape[0]))
        return 1.0 + self.hats @ g.T

    @property
    def causal(self) -> bool:
        """Whether the DAQ's filter runs on the outputs at the integrator's sub-steps
        (:class:`CausalFilter`, :class:`~wingopt.measurements.decimation_filter.DecimationFilter`)."""
        return isinstance(self.daq, (CausalFilter, DecimationFilter))

    def trajectory(self, theta: np.ndarray, every_substep: bool = False):
        """Modal displacements ``(N, B, m)`` for a batch of unknowns ``(B, dim)``; with
        ``every_substep`` the displacements and velocities at the integrator's sub-steps."""
        ph = self.physical(theta)
        amp = self.amplitude(ph["g"])[:-1]  # load held over each interval
        forces = amp[:, :, None] * (ph["c"] @ self._force_shapes)[None]
        bm = self.model
        par = (ph["prestrain_x"], ph["prestrain_y"], ph["damping"])
        return bm.simulate(ph["q0"], ph["v0"], forces, *par, nonlinear=self.nonlinear, every_substep=every_substep)

    # -- cost ------------------------------------------------------------------------------
    @cached_property
    def prior_matrix(self) -> np.ndarray:
        """Rows ``R`` of the prior cost ``|R theta|^2`` (the prestrains' correlation whitened)."""
        R = np.eye(self.dim)
        sl = self.slices
        free, r = self.prior.free, self.prior.correlation
        if r and "prestrain_x" in free and "prestrain_y" in free:
            i, j = (sl["par"].start + free.index(n) for n in ("prestrain_x", "prestrain_y"))
            L = np.linalg.cholesky(np.array([[1.0, r], [r, 1.0]]))
            R[np.ix_([i, j], [i, j])] = np.linalg.inv(L)
        if self.hats is not None:
            Rg = self.gust.prior_rows(self.t)
            block = np.zeros((Rg.shape[0], self.dim))
            block[:, sl["g"]] = Rg
            keep = np.ones(self.dim, bool)
            keep[sl["g"]] = False
            R = np.vstack([R[keep], block])
        return R

    def residuals(self, theta: np.ndarray, jacobian: bool = False):
        """Data residuals ``(n_data,)``, prior residuals, and (optionally) their Jacobians."""
        theta = np.asarray(theta, dtype=float)
        Rp = self.prior_matrix
        if not jacobian:
            _, pred = self.predicted(theta)
            return ((self.y - pred) / self.sigma)[self.valid], Rp @ theta
        if self.jacobian == "tangent":
            states = self._tangent(theta)  # Q, dQ (and V, dV at the sub-steps for a causal filter)
        else:
            traj = self.trajectory(theta + 1j * _H * np.eye(self.dim), self.causal)
            states = [x for X in (traj if self.causal else (traj,)) for x in (X[:, 0].real, X.imag / _H)]
        Qr, dQ = states[:2]
        CQ = self.model.sensor_products(Qr)
        pred = np.einsum("kpi,ki->kp", CQ, Qr)
        J = -2.0 * np.matmul(CQ, dQ.transpose(0, 2, 1)) / self.sigma[None, :, None]  # batched GEMM, not einsum
        if self.causal:  # linear: the Jacobian is the filter on the inputs' sensitivities, exact
            V, dV = states[2:]
            CV = self.model.sensor_products(V)
            Jd = -2.0 * (np.matmul(CV, dQ.transpose(0, 2, 1)) + np.matmul(CQ, dV.transpose(0, 2, 1)))
            pred, J = (
                self._filtered(pred, 2.0 * np.einsum("kpi,ki->kp", CQ, V)),
                self._filtered(J, Jd / self.sigma[:, None]),
            )
        elif self.daq is not None:  # a linear filter: the filtered prediction's Jacobian is the filtered Jacobian
            pred, J = self.daq(pred), self.daq(J)
        return ((self.y - pred) / self.sigma)[self.valid], Rp @ theta, J[self.valid], Rp

    def _filtered(self, h: np.ndarray, hd: np.ndarray) -> np.ndarray:
        """The causal filter's record of the outputs ``h`` and their rates ``hd`` at the sub-steps."""
        S = self.model.substeps
        return self.daq(h, hd, self.model.dt / S, S)

    def _tangent(self, theta: np.ndarray) -> tuple[np.ndarray, ...]:
        """Trajectory and its exact derivatives by the tangent-linear integrator (and, for a causal
        filter, at the sub-steps, with the velocities and theirs)."""
        ph = self.physical(theta)
        P, sl, m, ms = self.dim, self.slices, self.model.m, self.state_modes
        dq0, dv0 = np.zeros((P, m)), np.zeros((P, m))
        i0 = sl["x0"].start
        idx = np.arange(ms)
        dq0[i0 + idx, idx] = self.x0_std[:ms]
        dv0[i0 + ms + idx, idx] = self.x0_std[m : m + ms]
        dpar = np.zeros((3, P))
        for i, name in enumerate(self.prior.free):
            std = self.prior.mean_std(name)[1]
            j = PARAMETERS.index(name)
            dpar[j, sl["par"].start + i] = std * (ph[name][0] if name == "damping" else 1.0)
        c = ph["c"][0]
        amp = self.amplitude(ph["g"])[:, 0]
        fc = c @ self._force_shapes
        forces = amp[:-1, None] * fc[None]
        scaled = self.shapes.prior_std[:, None] * self._force_shapes
        base = np.zeros((P, m))
        base[sl["c"]] = scaled
        hats = np.zeros((amp.size, 0)) if self.hats is None else self.hats
        dforces = ForceTangent(amp, base, hats, sl["g"].start, fc)
        return self.model.simulate_tangent(
            ph["q0"][0],
            ph["v0"][0],
            forces,
            ph["prestrain_x"][0],
            ph["prestrain_y"][0],
            ph["damping"][0],
            dq0,
            dv0,
            dpar,
            dforces,
            self.nonlinear,
            self.causal,
        )

    def outputs(self, theta: np.ndarray) -> np.ndarray:
        """Predicted records ``(N, B, p)`` of a batch of unknowns ``(B, dim)``, the DAQ's filter
        included (a start-up's ranking of candidates on a filtered record)."""
        th = np.atleast_2d(np.asarray(theta, float))
        if self.causal:
            return self._causal_record(*(X.real for X in self.trajectory(th, True)))
        Q = self.trajectory(th).real
        flat = Q.reshape(-1, self.model.m)
        h = self.model.outputs(flat).reshape(Q.shape[:2] + (self.model.p,))
        return h if self.daq is None else self.daq(h)

    def _causal_record(self, Q: np.ndarray, V: np.ndarray) -> np.ndarray:
        """The causal filter's record ``(N, ..., p)`` of modal displacements ``Q`` and velocities ``V``
        ``(rows, ..., m)`` at the integrator's sub-steps: the outputs ``q^T C q`` and their rates."""
        bm = self.model
        flat_q, flat_v = Q.reshape(-1, bm.m), V.reshape(-1, bm.m)
        CQ = bm.sensor_products(flat_q)
        shape = Q.shape[:-1] + (bm.p,)
        h = np.einsum("kpi,ki->kp", CQ, flat_q).reshape(shape)
        return self._filtered(h, 2.0 * np.einsum("kpi,ki->kp", CQ, flat_v).reshape(shape))

    def predicted(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Modal trajectory ``(N, m)`` and predicted outputs ``(N, p)``."""
        th = np.asarray(theta, float)[None]
        if self.causal:
            Q, V = (X[:, 0].real for X in self.trajectory(th, True))
            return Q[:: self.model.substeps], self._causal_record(Q, V)
        Q = self.trajectory(th)[:, 0].real
        pred = self.model.outputs(Q)
        return Q, pred if self.daq is None else self.daq(pred)

    def load_history(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Shape coefficients ``c`` and amplitude ``1 + g(t_k)`` ``(N,)``."""
        ph = self.physical(np.asarray(theta, float))
        return ph["c"][0], self.amplitude(ph["g"])[:, 0]

    def lift(self, theta: np.ndarray) -> np.ndarray:
        """Lift history ``(N,)`` of the unknowns ``theta``: the shapes' lift times the amplitude."""
        c, amp = self.load_history(theta)
        return amp * float(self.shapes.lift_row @ c)
