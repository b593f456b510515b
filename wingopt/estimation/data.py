"""What every load estimator consumes and returns.

* :class:`Measurements`: sampled stretch-sensor outputs (simulated or measured), NaN where a
  sample is missing.
* :class:`IdentificationResult`: the estimated load and deflection histories, the lift with
  its 1-sigma band when the method provides one, and timing.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wingopt.errors import InputError

__all__ = ["Measurements", "IdentificationResult"]


@dataclass(frozen=True, eq=False)
class Measurements:
    """Stretch-sensor time series.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times (s), strictly increasing.
    values : ndarray, shape (N, p)
        Sensor outputs; NaN marks a missing sample (skipped by estimators, never invented).
    sensor_names : tuple of str
        Column names, in the order of the problem's sensors.
    noise_std : ndarray, shape (p,), optional
        Known noise standard deviation per sensor; ``None`` when it must be estimated.
    source : str
        Where the data came from (a file name, or ``"simulated L1 1% seed 0"``).
    """

    t: np.ndarray
    values: np.ndarray
    sensor_names: tuple[str, ...]
    noise_std: np.ndarray | None = None
    source: str = ""

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float)
        v = np.asarray(self.values, dtype=float)
        if t.ndim != 1 or v.ndim != 2 or v.shape[0] != t.size:
            raise InputError(f"measurements: t has shape {t.shape} and values {v.shape}, expected (N,) and (N, p)")
        if v.shape[1] != len(self.sensor_names):
            raise InputError(f"measurements: {v.shape[1]} columns for {len(self.sensor_names)} sensor names")
        if t.size and np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0)) + 1
            raise InputError(f"t[{k}] = {float(t[k])!r} after {float(t[k - 1])!r}: expected strictly increasing times")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "values", v)

    @property
    def count(self) -> int:
        return self.t.size

    @property
    def missing(self) -> np.ndarray:
        """Boolean ``(N,)``: rows with at least one missing value."""
        return np.isnan(self.values).any(axis=1)


@dataclass(eq=False)
class IdentificationResult:
    """Output of a load estimator on one data record.

    Attributes
    ----------
    method : str
        ``"mhe"``, ``"jekf"``, ...
    t : ndarray (N,)
        Times of the estimates.
    load : ndarray (N, n_load)
        Load coefficient estimates (in the estimator's load space) at each time.
    deflection : ndarray (N, n)
        Deflection coefficient estimates at each time.
    lift : ndarray (N,)
        ``∫ P_hat`` at each time, N.
    lift_std : ndarray (N,) or None
        1-sigma of the lift when the method gives a posterior covariance.
    regularization : float
        The lambda used.
    wall_s : float
        Wall time of the estimation (s).
    info : dict
        Method-specific diagnostics (iterations, solver statuses, lambda rule, ...).
    load_space : TensorSpace or None
        Basis of the ``load`` coefficients; ``None`` means the model's deflection basis.
    """

    method: str
    t: np.ndarray
    load: np.ndarray
    deflection: np.ndarray
    lift: np.ndarray
    lift_std: np.ndarray | None = None
    regularization: float = float("nan")
    wall_s: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)
    load_space: Any = None

    @property
    def final_load(self) -> np.ndarray:
        return self.load[-1]

    @property
    def final_deflection(self) -> np.ndarray:
        return self.deflection[-1]
