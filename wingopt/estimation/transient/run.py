"""One transient record's estimation as it runs: what every step of the fit shares.

:class:`RecordRun` holds the record, its settings (with the problem's declaration), the noise level,
the modal model, the load and parameter priors, the initial state's prior (checked against the
record's first samples: :mod:`.initial_shape`), the work budget that all its fits draw on, and the
monitors of the fits that stopped early (:mod:`.stopping`).
"""

from __future__ import annotations

import time

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.core.load_model import LoadShapes
from wingopt.estimation.core.load_prior import PriorScales, load_priors, prior_kinds
from wingopt.estimation.core.noise import resolve_noise_std
from wingopt.estimation.core.onset import quiet_lead
from wingopt.estimation.core.record_fit import Budget, Fit, levenberg_marquardt
from wingopt.estimation.core.record_problem import ParameterPrior, RecordProblem
from wingopt.estimation.core.record_settings import RecordSettings
from wingopt.estimation.core.start import initial_state_prior, modal_model, record_filter
from wingopt.estimation.transient.initial_shape import declared_start
from wingopt.estimation.transient.stopping import EarlyStop, arrived
from wingopt.measurements.series import Measurements
from wingopt.membrane import MembraneModel

__all__ = ["RecordRun"]


class RecordRun:
    """The shared state of one record's fits (``settings.declaration`` filled).

    Attributes
    ----------
    sigma, noise_source :
        Noise level per sensor and where it came from (the data's second differences unless given).
    p0 : float
        The prior load (Pa): the declaration's ``initial_load`` unless the caller gave one.
    bm, shapes, weigh_frame, prior :
        The modal model, the load shapes, whether the frame prior is weighed against them, and the
        parameter prior.
    x_mean, x_std, bubble_known :
        The initial state's prior, and whether it fixes the sign (a declared initial shape the
        record's start agrees with).
    initial_shape : dict
        The check of the declared initial shape against the record's first samples
        (:func:`.initial_shape.declared_start`; ``info["initial_shape"]``).
    budget, stops, skipped :
        The work budget, ``id(fit) -> (monitor, fit)`` of the fits that stopped early (the fit is
        kept so that its id is not reused while the record is estimated), and the alternatives the
        budget left unfitted.
    """

    def __init__(self, model: MembraneModel, meas: Measurements, s: RecordSettings, initial_load: float | None) -> None:
        self.model, self.meas, self.s = model, meas, s
        self.t0 = time.perf_counter()
        self.budget = Budget(s.max_total_iter, s.cpu_s)  # every fit of this record draws on it
        self.stops: dict[int, tuple[EarlyStop, Fit]] = {}
        self.skipped: list[str] = []
        ident = s.declaration
        dt = float(np.median(np.diff(meas.t)))
        acquisition = model.problem.acquisition
        sigma, self.noise_source = resolve_noise_std(
            meas.values, meas.sensor_names, None, meas.noise_std, ident.noise_std, acquisition=acquisition, fs=1 / dt
        )
        self.sigma = np.asarray(sigma, float)
        # a pre-trigger: the fit starts where the motion does
        self.lead = quiet_lead(meas.values, self.sigma, dt, acquisition)
        if self.lead:
            self.meas = meas = meas.since(self.lead)
        self.p0 = ident.initial_load if initial_load is None else float(initial_load)
        substeps = max(s.substeps, int(np.ceil(dt / s.substep_s - 1e-9)))
        self.bm = modal_model(
            model, s.membrane_model, min(s.modes, model.n), dt, substeps, s.stretch_gain, s.cubic_modes
        )
        self.daq = record_filter(model.problem)
        self.shapes, self.weigh_frame = _load_prior(model, self.p0, s)
        self.prior = ParameterPrior.from_problem(model.problem, s.free, s.prestrain_rel, s.damping_rel, ident)
        self._initial_state(ident.initial_deflection)

    def _initial_state(self, peak: float) -> None:
        """The initial state's prior: the declared shape unless the record's start contradicts it."""
        problem, y = self.model.problem, self.meas.values
        self.initial_shape = declared_start(self.bm, problem, peak, self.meas.t, y, self.sigma)
        if self.initial_shape["contradicted"]:
            peak = 0.0  # unknown: the prior at the data's scale, the sign from the prior load
        self.x_mean, self.x_std, self.bubble_known = initial_state_prior(self.bm, problem, y, peak)

    def fit(self, r: RecordProblem, theta0: np.ndarray, cap: RecordSettings | None = None, rules=()) -> Fit:
        """Levenberg–Marquardt on ``r`` from ``theta0`` within the record's budget (``cap.max_iter``
        iterations at most; ``rules``: its early stops, when ``stop_early``, and then the lift's
        convergence test, :func:`.stopping.arrived`)."""
        cap = self.s if cap is None else cap
        if not (rules and self.s.stop_early):
            return levenberg_marquardt(r, theta0, cap.max_iter, budget=self.budget)
        monitor = EarlyStop((*rules, arrived(r)))  # a rule that stops it short first, as before
        f = levenberg_marquardt(r, theta0, cap.max_iter, budget=self.budget, monitor=monitor)
        if f.stopped is not None:
            self.stops[id(f)] = (monitor, f)
        return f

    def stopped(self, fit: Fit) -> EarlyStop | None:
        """The monitor that stopped ``fit`` early, if one did."""
        return self.stops.get(id(fit), (None,))[0]

    def problem(self, shapes: LoadShapes, nonlinear: bool) -> RecordProblem:
        """The record's least-squares problem on ``shapes`` (constant load)."""
        s = self.s
        return RecordProblem(
            self.bm,
            shapes,
            self.meas.t,
            self.meas.values,
            self.sigma,
            self.prior,
            self.x_mean,
            self.x_std,
            None,
            nonlinear,
            min(s.state_modes, self.bm.m),
            daq=self.daq,
        )


def _load_prior(model: MembraneModel, p0: float, s: RecordSettings) -> tuple[LoadShapes, bool]:
    """The load shapes of a transient record and whether the frame prior is weighed against them
    (``[identification] pressure_prior``: ``auto`` weighs, ``interior``/``frame``/``aerodynamic``
    take one; the settings' ``edge_shapes`` take the shapes as given: the frame prior's with them,
    not weighed)."""
    d = s.declaration
    if d.pressure_prior == "aerodynamic" and not d.leading_edge:
        raise InputError(
            "[identification] pressure_prior = 'aerodynamic' on a transient record: needs leading_edge = 'x0' "
            "or 'x1' (which edge the flow meets)"
        )
    kinds = prior_kinds(d, auto=("interior",))
    if s.edge_shapes and kinds != ("aerodynamic",):
        kinds = ("frame",)
    ((_, shapes),) = load_priors(model, kinds, p0, PriorScales.of(s), d.leading_edge)
    return shapes, s.frame == "auto" and d.pressure_prior == "auto" and not s.edge_shapes
