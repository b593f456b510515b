"""The pressure field behind the reported lift, its per-point band, and the field over time.

An identification reports one lift (:attr:`IdentificationResult.reported_lift`), and the field a
lab takes home must be the one that lift is the integral of:

* **a steady record** (the steady route of four sensors, the DIC full field: ``info["steady_lift_N"]``
  set) reports the record's *mean* lift; the field behind it is the time mean of the estimated
  field over every sample with an estimate (the load coefficients' mean: the field is linear in
  them). Its integral is the mean of the lift history (the chosen load prior's); when the evidence
  splits the lift between load priors the reported lift is their mixture, and the difference is
  in ``field_lift_N`` beside ``lift_N`` (on the shipped stand-in, every route: within 0.04 %).
* **a transient record** (the whole-record and windowed estimators, the stream) reports the *last*
  estimate; the field behind it is the last sample's.

The per-point band (``pressure_std_Pa``) is the reported lift's relative 1-sigma carried to every
point: ``std P(x) = |P(x)| * lift_std / |lift|``. It is the band of the field's *amplitude*: on these
routes the lift's uncertainty is the load's scale (the tension, which the sensors' ``(p/T)^2``
cannot separate from the pressure, scales the whole field; the load prior fixes the shape), and the
estimators return the lift's posterior, not the covariance of every point. It does not hold the
shape's uncertainty. Where the field keeps one sign, the band integrates to the lift's band.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["MeanField", "mean_field", "grid", "field_history", "basis_space"]


def basis_space(result, model) -> Any:
    """The :class:`~wingopt.fe.space.TensorSpace` of ``result.load`` (the model's space when ``None``;
    a :class:`~wingopt.estimation.core.load_space.LoadSpace` carries one)."""
    space = result.load_space if result.load_space is not None else model.space
    return space if hasattr(space, "basis_matrix") else space.space


def grid(problem, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """``X, Y`` ``(ny, nx)`` of a uniform grid over the membrane, edges included (m)."""
    xs = np.linspace(0.0, problem.width, shape[0])
    ys = np.linspace(0.0, problem.height, shape[1])
    return np.meshgrid(xs, ys)


@dataclass(frozen=True, eq=False)
class MeanField:
    """The pressure field behind a reported lift (see the module docstring).

    Attributes
    ----------
    space : TensorSpace
        Basis of ``coefficients``.
    coefficients : ndarray (n,)
        The field's coefficients (Pa).
    lift_N, lift_std_N : float, float or None
        The reported lift and its 1-sigma (``None``: the estimator gives no band).
    field_lift_N : float
        The field's own integral (N).
    kind : str
        ``"mean"`` (the time mean of a steady record's field) or ``"last"`` (the last estimate).
    samples : int
        Samples averaged (1 for ``"last"``).
    """

    space: Any
    coefficients: np.ndarray
    lift_N: float
    lift_std_N: float | None
    field_lift_N: float
    kind: str
    samples: int

    @property
    def relative_band(self) -> float:
        """``lift_std / |lift|`` (NaN without a band)."""
        if self.lift_std_N is None or not np.isfinite(self.lift_std_N) or self.lift_N == 0:
            return float("nan")
        return float(self.lift_std_N / abs(self.lift_N))

    def __call__(self, x, y) -> np.ndarray:
        """Pressure (Pa) at points ``x, y`` (any shape, m)."""
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        return np.asarray(self.space.evaluate(self.coefficients, x.ravel(), y.ravel())).reshape(x.shape)

    def std(self, x, y) -> np.ndarray:
        """The per-point 1-sigma (Pa): ``|P(x, y)| * lift_std / |lift|``."""
        return np.abs(self(x, y)) * self.relative_band

    def as_dict(self) -> dict:
        """What ``summary.json`` says of the field (``mean_field``)."""
        how = (
            f"time mean of the estimated field over {self.samples} samples (the record's mean lift)"
            if self.kind == "mean"
            else "the last sample's estimated field (the reported lift is the last estimate)"
        )
        return {
            "kind": self.kind,
            "samples": self.samples,
            "field_lift_N": self.field_lift_N,
            "lift_N": self.lift_N,
            "relative_difference": self.field_lift_N / self.lift_N - 1.0 if self.lift_N else float("nan"),
            "what": how,
            "band": "pressure_std_Pa = |pressure_Pa| * lift_std_N / |lift_N| (the amplitude's band)",
        }


def integral(space, coefficients: np.ndarray, order: int = 4) -> np.ndarray:
    """``∫ P`` (N) of coefficients ``(n,)`` or ``(n, m)`` by Gauss quadrature (exact for the cubic splines)."""
    x, y, w = space.cells().quadrature(order)
    return w.ravel() @ (space.basis_matrix(x.ravel(), y.ravel()) @ coefficients)


def mean_field(result, model) -> MeanField:
    """The field behind ``result.reported_lift`` (module docstring) in the result's load space.

    Parameters
    ----------
    result : IdentificationResult
    model : MembraneModel
        The estimator's model (its space when the result names no load space).

    Returns
    -------
    MeanField
    """
    space = basis_space(result, model)
    lift, std = result.reported_lift
    load = np.asarray(result.load, dtype=float)
    ok = np.all(np.isfinite(load), axis=1) if load.ndim == 2 and load.shape[1] else np.zeros(len(load), bool)
    if not np.any(ok):
        coef, kind, n = np.full(space.n, np.nan), "last", 0
    elif result.info.get("steady_lift_N") is not None:
        coef, kind, n = load[ok].mean(axis=0), "mean", int(np.count_nonzero(ok))
    else:
        coef, kind, n = load[np.flatnonzero(ok)[-1]], "last", 1
    return MeanField(space, coef, lift, std, float(integral(space, coef)), kind, n)


def field_history(result, model, X: np.ndarray, Y: np.ndarray, index=None) -> tuple[np.ndarray, np.ndarray]:
    """The estimated field at the samples ``index`` (default all) on the grid ``X, Y``.

    Returns
    -------
    t : ndarray (m,)
    pressure : ndarray (m, ny, nx)
        Pa; NaN where a sample has no estimate.
    """
    space = basis_space(result, model)
    idx = np.arange(len(result.t)) if index is None else np.asarray(index, dtype=int)
    load = np.asarray(result.load, dtype=float)[idx]
    if load.ndim != 2 or load.shape[1] != space.n:
        return np.asarray(result.t)[idx], np.full((idx.size, *X.shape), np.nan)
    B = space.basis_matrix(X.ravel(), Y.ravel())
    P = np.asarray((B @ np.nan_to_num(load).T).T)
    P[~np.all(np.isfinite(load), axis=1)] = np.nan
    return np.asarray(result.t)[idx], P.reshape(idx.size, *X.shape)
