"""Configuration of the moving-horizon estimator (:class:`MHESettings`) and its named constants."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.core.lambda_rules import resolve as resolve_rule
from wingopt.estimation.core.load_space import LoadSpaceKind
from wingopt.estimation.core.regularization import LambdaRule
from wingopt.estimation.mhe.solvers import WINDOW_SOLVERS
from wingopt.estimation.options import option
from wingopt.optim.registry import solver_names
from wingopt.problem.membrane import IdentificationSettings

__all__ = ["MHESettings", "LOAD_MODELS", "STATE_PRIOR_EVIDENCE", "SIGN_MARGIN"]

LOAD_MODELS = ("constant", "random_walk")

STATE_PRIOR_EVIDENCE = (1.0, 0.1, 0.01, 0.001)
"""Candidates of ``MHESettings.state_prior_choices`` for the evidence-chosen state prior."""

SIGN_MARGIN = 0.1
"""Below this agreement with the prior (:func:`~wingopt.estimation.mhe.cold_start.sign_score`) the sign
is reported as undetermined (e.g. L2, no net lift, without an initial-deflection prior)."""


# How the identification options (wingopt.estimation.options) set these settings.
def _duration(name: str):
    """A window or stride: whole samples (``int``) or seconds (the ``_s`` field)."""
    return lambda v: {name if isinstance(v, int) else f"{name}_s": v}


def _load_model(value: str) -> dict:
    return {"load_model": "random_walk" if value == "varying" else "constant"}


def _lambda(choice) -> dict:
    if choice.is_fixed:
        return {"regularization": choice.value}
    return {"regularization": None, "lambda_rule": resolve_rule(choice.rule, "mhe").internal}


def _state_prior(value) -> dict:
    return {"state_prior_choices": STATE_PRIOR_EVIDENCE} if value == "evidence" else {"state_prior": value}


@dataclass(frozen=True)
class MHESettings:
    """Configuration of the moving-horizon estimator.

    Parameters
    ----------
    window_s, stride_s : float
        Window length and step in **seconds** (defaults 0.2 s and 0.05 s): the window then holds the
        same stretch of physics at any sample rate (200/50 samples at 1 kHz, 60/15 at 300 Hz). With
        the random-walk load model the window is rounded to whole strides.
    window, stride : int or None
        Window length and step in **samples**; when given they override ``window_s``/``stride_s``
        (``1 <= stride <= window``). The estimator solves ``(samples - window) / stride + 1``
        windows (plus restarts, see ``consistency``).
    load_model : {"constant", "random_walk"}
        ``constant``: one load, constant in time; its information accumulates without forgetting
        (the last window reproduces the batch estimate over the record), and a change of the load
        is caught by the consistency test, which restarts the estimate (quasi-static loads, the
        protocol, a steady wind-tunnel run). ``random_walk``: the window holds ``window / stride``
        load blocks of ``stride`` samples that follow a random walk (process noise, see
        ``load_timescale``) within and across windows (slowly varying loads).
    load_timescale : float
        Random walk only: ``T_a`` (s) over which the load's amplitude may change by its own size
        (1 sigma of the random walk; :mod:`wingopt.estimation.mhe.load_model`). The same process
        noise forgets old load information in the arrival cost.
    shape_timescale : float
        Random walk only: ``T_s`` (s), the same for the load's shape (the pressure distribution),
        which steady data barely see (4 sensors): it must change much more slowly than the
        amplitude or the estimate drifts along what the sensors cannot see.
    consistency : bool
        Chi-square consistency tests (:mod:`wingopt.estimation.mhe.consistency`): samples at the
        start of the record that the load model cannot explain (the load's onset) are left out of
        the start-up, and a window whose data become inconsistent with the estimate restarts it.
    consistency_segment_s : float
        Length (s) of the segments tested (at least 3 samples).
    modes : int or None
        Membrane modes kept (``None``: all). 40 keeps the steady sensor outputs of L1–L3 within
        0.3 %; the estimates with 30, 40, 60 and 100 modes agree to 3 digits (measured).
    load_space : {"fixed", "free"}
        Load basis (:mod:`wingopt.estimation.core.load_space`).
    backend : {"numpy", "cvxpy", "ipopt"}
        Window solver (:mod:`wingopt.estimation.mhe.solvers`).
    qp_solver : {"clarabel", "osqp", "daqp"}
        QP solver of the cvxpy backend.
    regularization : float or None
        Fixed lambda; ``None``: choose it from the data with ``lambda_rule``.
    lambda_rule : {"robust", "discrepancy", "gcv"}
    lambda_grid : tuple of float
        Relative lambdas tried by the rule (multiples of the problem's natural scale, see
        :meth:`MovingHorizonEstimator.natural_lambda`); the bracket of the chosen one is refined once.
    state_prior : float
        Prior standard deviation of the initial modal state, relative to the data's amplitude:
        ``state_prior * A / omega_j`` for displacements and ``state_prior * A`` for velocities
        (a weak prior scaled like ``1/omega``: equal energy per mode).
    state_prior_choices : tuple of float
        When given, ``state_prior`` is chosen among these by the Laplace evidence of the first
        window (:meth:`MovingHorizonEstimator.setup`); empty (default): ``state_prior`` as given.
        ``STATE_PRIOR_EVIDENCE`` = (1, 0.1, 0.01, 0.001) is the documented set: with the protocol's
        bubble as prior the evidence prefers 1e-3 by 190–215 log units, so a known initial state
        is confirmed by the data (``docs/estimation.md``). It helps the free-edge space on L3 and
        is not the default: with the fixed space it degrades L1/L2 at 5 % noise (measured).
    state_noise : float
        Relative process noise on the modal state per window step (model error; also keeps the
        propagated arrival information finite for fast-decaying modes).
    band_decades : float
        The lift's 1-sigma band averages the Laplace posterior over ``lambda`` log-uniform within
        this many decades of the chosen one (the resolution of the lambda rule); 0: the plain
        Laplace band at the chosen ``lambda``. 0.9 was calibrated to the nominal 68 % coverage on
        noise seeds 100–119 (L1, 5 %), disjoint from the seeds the studies report
        (``docs/estimation.md``).
    pressure_bounds : (float, float) or None
        ``(min, max)`` pressure in Pa at the points of ``bound_grid`` (cvxpy and ipopt backends).
    bound_grid : (int, int)
        Points in x and y (edges included) where the bounds are imposed.
    max_iterations, tolerance : int, float
        Window solver limits; ``tolerance`` in chi-square units.
    start_shapes, start_state_modes, start_amplitudes : int
        Size of the start-up scan and coarse problem (:func:`~wingopt.estimation.mhe.cold_start.start_window`).
    declaration : IdentificationSettings or None
        What the problem file declares for identification (its ``[identification]``: the sample
        period, the noise, the sign prior ``initial_load`` and ``initial_deflection``). The builder
        fills it from the problem (:func:`~wingopt.estimation.declaration.with_declaration`), and so
        does :class:`MovingHorizonEstimator` when it is still ``None``; a caller may give its own.
        The estimator reads it here, never the problem.
    """

    window_s: float = 0.2
    stride_s: float = 0.05
    window: int | None = field(default=None, metadata=option("window", _duration("window")))
    stride: int | None = field(default=None, metadata=option("stride", _duration("stride")))
    load_model: str = field(default="constant", metadata=option("load_model", _load_model))
    load_timescale: float = field(default=1.0, metadata=option("load_timescale"))
    shape_timescale: float = 100.0
    consistency: bool = field(default=True, metadata=option("consistency"))
    consistency_segment_s: float = 0.01
    modes: int | None = field(default=40, metadata=option("modes"))
    load_space: str = field(default="fixed", metadata=option("load_space"))
    backend: str = field(default="numpy", metadata=option("solver"))
    qp_solver: str = field(default="clarabel", metadata=option("qp_solver"))
    regularization: float | None = field(default=None, metadata=option("lam", _lambda))
    lambda_rule: str = "robust"
    lambda_grid: tuple[float, ...] = tuple(10.0 ** np.arange(-6.0, 0.01, 1.0))
    state_prior: float = field(default=1.0, metadata=option("state_prior", _state_prior))
    state_prior_choices: tuple[float, ...] = ()
    state_noise: float = 1e-6
    band_decades: float = 0.9
    pressure_bounds: tuple[float, float] | None = field(default=None, metadata=option("pressure_bounds"))
    bound_grid: tuple[int, int] = (15, 8)
    max_iterations: int = 100
    tolerance: float = 1e-2
    start_shapes: int = 3
    start_state_modes: int = 4
    start_amplitudes: int = 16
    declaration: IdentificationSettings | None = None

    def __post_init__(self) -> None:
        def bad(name, expected):
            raise InputError(f"mhe {name} = {getattr(self, name)!r}: expected {expected}")

        if not (np.isfinite(self.window_s) and self.window_s > 0):
            bad("window_s", "a positive duration (s)")
        if not (np.isfinite(self.stride_s) and 0 < self.stride_s <= self.window_s):
            bad("stride_s", f"a duration in (0, window_s = {self.window_s}] (s)")
        if self.window is not None and (int(self.window) != self.window or self.window < 2):
            bad("window", "an integer >= 2 (samples) or None (window_s)")
        if self.stride is not None and (int(self.stride) != self.stride or self.stride < 1):
            bad("stride", "a positive integer (samples) or None (stride_s)")
        if self.window is not None and self.stride is not None and self.stride > self.window:
            bad("stride", f"an integer in 1..window ({self.window})")
        if self.load_model not in LOAD_MODELS:
            bad("load_model", " or ".join(LOAD_MODELS))
        if (
            self.load_model == "random_walk"
            and self.window is not None
            and self.stride is not None
            and self.window % self.stride
        ):
            bad("stride", f"a divisor of the window ({self.window}) for the random-walk load model")
        if not (np.isfinite(self.load_timescale) and self.load_timescale > 0):
            bad("load_timescale", "a positive time (s)")
        if not (np.isfinite(self.shape_timescale) and self.shape_timescale > 0):
            bad("shape_timescale", "a positive time (s)")
        if not (np.isfinite(self.consistency_segment_s) and self.consistency_segment_s > 0):
            bad("consistency_segment_s", "a positive duration (s)")
        if self.modes is not None and (int(self.modes) != self.modes or self.modes < 1):
            bad("modes", "a positive integer or None (all)")
        try:
            LoadSpaceKind(self.load_space)
        except ValueError:
            bad("load_space", "'fixed' or 'free'")
        if self.backend not in WINDOW_SOLVERS:
            bad("backend", "one of " + ", ".join(WINDOW_SOLVERS))
        if self.qp_solver not in solver_names("least-distance"):
            bad("qp_solver", "one of " + ", ".join(solver_names("least-distance")))
        if self.regularization is not None and not (np.isfinite(self.regularization) and self.regularization > 0):
            bad("regularization", "a positive number or None (from the data)")
        try:
            LambdaRule(self.lambda_rule)
        except ValueError:
            bad("lambda_rule", "robust, discrepancy or gcv")
        if len(self.lambda_grid) < 3 or min(self.lambda_grid) <= 0:
            bad("lambda_grid", "at least 3 positive numbers")
        if not self.state_prior > 0:
            bad("state_prior", "a positive number")
        if any(not (np.isfinite(c) and c > 0) for c in self.state_prior_choices):
            bad("state_prior_choices", "positive numbers (empty: use state_prior)")
        if not self.state_noise > 0:
            bad("state_noise", "a positive number")
        if not self.band_decades >= 0:
            bad("band_decades", "a non-negative number of decades")
        if self.pressure_bounds is not None:
            lo, hi = self.pressure_bounds
            if not lo < hi:
                bad("pressure_bounds", "(min, max) with min < max (Pa)")
            if self.backend == "numpy":
                raise InputError("mhe pressure_bounds need backend cvxpy or ipopt (numpy has no bounds)")

    def replace(self, **changes: Any) -> MHESettings:
        return dataclasses.replace(self, **changes)

    def samples(self, dt: float) -> tuple[int, int]:
        """Window length and stride in samples at sample period ``dt`` (s).

        Samples given explicitly win; otherwise ``window_s`` and ``stride_s`` are rounded to whole
        samples, and for the random walk the window to whole strides.
        """
        stride = int(self.stride) if self.stride is not None else max(1, int(round(self.stride_s / dt)))
        if self.window is not None:
            window = int(self.window)
        else:
            window = max(2, int(round(self.window_s / dt)))
            if self.load_model == "random_walk":
                window = stride * max(1, int(round(window / stride)))
        if stride > window:
            raise InputError(f"mhe stride = {stride} samples exceeds the window ({window} samples)")
        if self.load_model == "random_walk" and window % stride:
            raise InputError(f"mhe stride = {stride}: not a divisor of the window ({window}) for the random walk")
        return window, stride
