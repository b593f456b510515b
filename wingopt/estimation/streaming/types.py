"""Settings and per-sample output of the streaming estimator (:mod:`wingopt.estimation.streaming`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.mhe import MHESettings

__all__ = ["StreamSettings", "Estimate"]


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
    """

    mhe: MHESettings = field(default_factory=MHESettings)
    startup_windows: float = 2.0
    relinearize: int = 4
    min_samples: int = 20
    trust: float = 1.0
    provisional_state_modes: int = 8

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


@dataclass(frozen=True, eq=False)
class Estimate:
    """The estimate after one sample.

    Attributes
    ----------
    k, t : int, float
        Sample index (from 0) and time (s).
    lift, lift_std : float
        Lift (N) and its 1-sigma (N); NaN and inf while ``phase == "waiting"``.
    load : ndarray or None
        Load coefficients in the load space (``None`` while waiting).
    chi2_per_datum : float
        Misfit per datum of the window (1 for data explained to the noise level).
    adequate : bool
        Misfit within the chi-square bound (see the module docstring).
    phase : str
        ``waiting``, ``provisional``, ``startup`` (the sample that ran the batch start-up) or ``tracking``.
    """

    k: int
    t: float
    lift: float
    lift_std: float
    load: np.ndarray | None
    chi2_per_datum: float
    adequate: bool
    phase: str
