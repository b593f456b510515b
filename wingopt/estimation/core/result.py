"""What every load estimator returns: :class:`IdentificationResult`, and :class:`Estimate` per sample.

The estimated load and deflection histories, the lift with its 1-sigma band when the method
provides one, timing and the estimator's diagnostics (what it consumes is
:class:`wingopt.measurements.Measurements`). A streaming estimator also returns one
:class:`Estimate` per sample it is pushed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wingopt.errors import MissingExtraError
from wingopt.estimation.core.diagnostics import Diagnostics
from wingopt.status import RunStatus, from_info

__all__ = ["IdentificationResult", "Estimate"]


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
    def diagnostics(self) -> Diagnostics:
        """What the estimator says of its answer, typed (:class:`~wingopt.estimation.core.diagnostics.Diagnostics`):
        its warnings, adequacy, convergence, steady lift and parameters, read from ``info``."""
        return Diagnostics.of(self.info)

    @property
    def reported_lift(self) -> tuple[float, float | None]:
        """The lift a summary reports and its 1-sigma: the last estimate, or for a steady record (the
        steady estimator's, the DIC frames': ``diagnostics.steady_lift``) the steady lift, which the
        history fluctuates about."""
        steady = self.diagnostics.steady_lift
        if steady is not None:
            return steady
        return float(self.lift[-1]), None if self.lift_std is None else float(self.lift_std[-1])

    @property
    def status(self) -> RunStatus:
        """One word for the run (:class:`~wingopt.status.RunStatus`): ``converged``, ``misfit`` (the
        model does not explain the data), ``not_converged`` or ``failed`` (no finite lift)."""
        return from_info(self.info, self.reported_lift[0] if len(self.lift) else float("nan"))

    def __repr__(self) -> str:
        # The default repr prints every array (15 000 characters for 0.3 s of data): a notebook
        # needs the answer, its band and whether to trust it.
        n = len(self.t)
        if not n:
            return f"IdentificationResult(method={self.method!r}, no samples, status='{self.status}')"
        lift, std = self.reported_lift
        band = "" if std is None else f" ± {std:.3g}"
        return (
            f"IdentificationResult(method={self.method!r}, lift={lift:.4g}{band} N, status='{self.status}', "
            f"samples={n}, t={self.t[0]:.4g}..{self.t[-1]:.4g} s, load coefficients={self.load.shape[-1]}, "
            f"lambda={self.regularization:.3g}, wall={self.wall_s:.3g} s)"
        )

    def to_dataframe(self):
        """The lift history with its 1-sigma band as a :class:`pandas.DataFrame`.

        Index ``t`` (s); columns ``lift_N`` and, with a band, ``lift_std_N``, ``lift_lo_N``,
        ``lift_hi_N``; ``attrs``: the reported lift and its band (``lift_N``, ``lift_std_N``), the
        method and the units. Needs pandas (``pip install 'wingopt[data]'``).
        """
        try:
            import pandas as pd  # optional: the data extra
        except ImportError:
            raise MissingExtraError("pandas is not installed: pip install 'wingopt[data]'") from None
        lift = np.asarray(self.lift, dtype=float)
        cols = {"lift_N": lift}
        if self.lift_std is not None:
            std = np.asarray(self.lift_std, dtype=float)
            cols.update(lift_std_N=std, lift_lo_N=lift - std, lift_hi_N=lift + std)
        df = pd.DataFrame(cols, index=pd.Index(np.asarray(self.t, dtype=float), name="t"))
        reported, band = self.reported_lift if len(lift) else (float("nan"), None)
        df.attrs.update(lift_N=reported, lift_std_N=band, method=self.method, units={"t": "s", "lift": "N"})
        return df

    @property
    def final_load(self) -> np.ndarray:
        return self.load[-1]

    @property
    def final_deflection(self) -> np.ndarray:
        return self.deflection[-1]
