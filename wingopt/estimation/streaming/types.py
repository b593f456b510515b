"""Settings and per-sample output of the streaming estimators (:mod:`wingopt.estimation.streaming`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.mhe import MHESettings
from wingopt.estimation.options import option
from wingopt.problem.membrane import IdentificationSettings

__all__ = ["StreamSettings", "NonlinearStreamSettings", "SampleClock", "STREAM_MHE_OPTIONS"]

STREAM_MHE_OPTIONS = ("lam", "window", "modes", "state_prior", "load_space", "solver", "qp_solver")
"""The options of the MHE that a stream takes (no stride, load model or bounds: it steps per sample)."""


@dataclass(frozen=True)
class StreamSettings:
    """Configuration of the streaming estimator.

    Parameters
    ----------
    mhe : MHESettings
        Window length (``window_s`` or ``window``), modes, load space, lambda rule, start-up; the
        batch start-up uses them as they are. Only the constant load model is supported.
    startup_windows : float
        The batch start-up runs once this many windows of samples have arrived (2: room to skip a
        load onset of up to one window, as the batch does).
    relinearize : int
        Window rows re-linearised per sample (round robin) besides the new one.
    min_samples : int
        Samples before the first (provisional) estimate (the noise estimate needs ~20).
    trust : float
        Largest Gauss–Newton step in the scaled unknowns (2-norm; the provisional phase starts
        far from the optimum).
    provisional_state_modes : int
        The provisional phase estimates the initial state of this many lowest modes only; the
        others are held at the prior (the problem's bubble, or rest). A cheaper, cruder estimate
        (16 + m instead of 3m unknowns) until the batch start-up replaces it.
    declaration : IdentificationSettings or None
        What the problem file declares for identification (its ``[identification]``: noise,
        initial load and shape), filled by the builder from the problem file
        (:func:`~wingopt.estimation.declaration.with_declaration`, at the stream's construction;
        ``None`` until then); a caller may give its own. The stream reads it here, never the problem.
    """

    mhe: MHESettings = field(default_factory=MHESettings, metadata=option(uses=STREAM_MHE_OPTIONS))
    startup_windows: float = 2.0
    relinearize: int = 4
    min_samples: int = 20
    trust: float = 1.0
    provisional_state_modes: int = 8
    declaration: IdentificationSettings | None = None

    def __post_init__(self) -> None:
        if self.mhe.load_model != "constant":
            raise InputError(f"streaming load_model = {self.mhe.load_model!r}: only 'constant' is supported")
        if not (np.isfinite(self.startup_windows) and self.startup_windows >= 1):
            raise InputError(f"streaming startup_windows = {self.startup_windows!r}: expected a number >= 1")
        if int(self.relinearize) != self.relinearize or self.relinearize < 0:
            raise InputError(f"streaming relinearize = {self.relinearize!r}: expected a non-negative integer")
        if int(self.min_samples) != self.min_samples or self.min_samples < 20:
            raise InputError(f"streaming min_samples = {self.min_samples!r}: expected an integer >= 20")
        if int(self.provisional_state_modes) != self.provisional_state_modes or self.provisional_state_modes < 0:
            raise InputError(
                f"streaming provisional_state_modes = {self.provisional_state_modes!r}: expected an integer >= 0"
            )
        if not self.trust > 0:
            raise InputError(f"streaming trust = {self.trust!r}: expected a positive number")


@dataclass(frozen=True)
class NonlinearStreamSettings:
    """Settings of :class:`NonlinearStreamingEstimator` (model defaults: the batch realistic estimator's).

    Attributes
    ----------
    modes, shapes, state_modes, substeps, substep_s, kappa, prior_power :
        As :class:`~wingopt.estimation.records.RecordSettings` (all modes dynamic).
    free : tuple of str or None
        Free parameters (some of ``prestrain_x, prestrain_y, damping``); ``None``: the problem file's.
    tracking_substeps : int
        Integration sub-steps per sample of the filter, at least one per 1 ms (default 1: one at
        1 kHz, four at 300 Hz); the start-up fit uses the batch's ``substeps``. The oscillator
        step is exact for a constant tension, so after the start-up transient one
        predictor-corrector step per sample loses nothing measurable (L1 protocol: final lift
        within 2e-6 of the 2-sub-step filter) at about half the work; in a fast transient (a
        gust, the provisional phase) its error is 2.3e-2 of the peak output instead of 6.1e-3
        (docs/estimation_records.md).
    load_walk : float
        Random walk of the load coefficients, in prior stds per sqrt(s) (default 0: a constant
        load, as the batch; measured: 0.002 makes the lift drift -1.2 % per minute of steady
        data on the L1 protocol, outside its band).
    min_samples : int
        Samples before the first estimate (>= 20: the first noise estimate).
    startup_s : float
        When the noise level is re-estimated and the buffered samples are fitted by the batch (s).
    window_s : float
        Window of the innovation chi-square (s).
    membrane_model : {"berger", "fvk"}
        The nonlinear membrane: the Berger model or the cubic modal FvK model of the batch
        default (``cubic_modes`` of its modes with FvK's cubic stiffness).
    declaration : IdentificationSettings or None
        What the problem file declares for identification (its ``[identification]``: noise,
        initial load and shape, parameter priors), filled by the builder from the problem file
        (:func:`~wingopt.estimation.declaration.with_declaration`, at the stream's construction;
        ``None`` until then); a caller may give its own. The stream reads it here, never the problem.
    """

    modes: int = field(default=48, metadata=option("modes"))
    shapes: int = 15
    state_modes: int = 12
    substeps: int = 2
    substep_s: float = 0.5e-3
    tracking_substeps: int = 1
    kappa: float = 1.0
    prior_power: float = 1.0
    free: tuple[str, ...] | None = None
    load_walk: float = 0.0
    min_samples: int = 20
    startup_s: float = 0.3
    window_s: float = 0.1
    membrane_model: str = "berger"
    cubic_modes: int = 16
    declaration: IdentificationSettings | None = None

    def __post_init__(self) -> None:
        if self.membrane_model not in ("berger", "fvk"):
            raise InputError(f"nonlinear streaming membrane_model = {self.membrane_model!r}: expected berger or fvk")
        for name, low in (
            ("modes", 1),
            ("shapes", 1),
            ("state_modes", 1),
            ("substeps", 1),
            ("tracking_substeps", 1),
            ("min_samples", 20),
            ("cubic_modes", 1),
        ):
            val = getattr(self, name)
            if int(val) != val or val < low:
                raise InputError(f"nonlinear streaming {name} = {val!r}: expected an integer >= {low}")
        for name in ("substep_s", "startup_s", "window_s", "kappa"):
            val = getattr(self, name)
            if not (np.isfinite(val) and val > 0):
                raise InputError(f"nonlinear streaming {name} = {val!r}: expected a positive number")
        if not (np.isfinite(self.load_walk) and self.load_walk >= 0):
            raise InputError(f"nonlinear streaming load_walk = {self.load_walk!r}: expected a number >= 0")


class SampleClock:
    """The checks of one pushed sample, shared by the streaming estimators.

    ``y`` must hold one value per sensor (NaN = missing) and ``t`` be finite; the first step fixes
    the sample period ``dt`` (increasing times), later steps must match it within ``JITTER``
    (relative): gaps are filled with missing samples by the reader, not skipped.
    """

    JITTER = 0.01

    def __init__(self, names) -> None:
        self.names = tuple(names)
        self.dt: float | None = None
        self.t_prev: float | None = None

    def accept(self, t: float, y) -> tuple[float, np.ndarray]:
        """``(t, y)`` as a float and a fresh 1-D array, after the checks; raises :class:`InputError`."""
        t = float(t)
        y = np.array(y, dtype=float).reshape(-1)  # a copy: the estimators buffer it
        if y.size != len(self.names):
            raise InputError(f"push: {y.size} values for {len(self.names)} sensors ({', '.join(self.names)})")
        if not np.isfinite(t):
            raise InputError(f"push: t = {t!r}: expected a finite time (s)")
        if self.t_prev is not None:
            step = t - self.t_prev
            if self.dt is None:
                if not step > 0:
                    raise InputError(f"push: t = {t!r} after {self.t_prev!r}: expected increasing times")
                self.dt = step
            elif abs(step / self.dt - 1.0) > self.JITTER:
                raise InputError(
                    f"push: t = {t!r} after {self.t_prev!r}: expected the sample period {self.dt:.6g} s "
                    "(fill gaps with missing samples)"
                )
        self.t_prev = t
        return t, y
