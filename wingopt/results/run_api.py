"""What an :class:`~wingopt.workflows.identify.IdentifyRun` offers a notebook beyond its numbers:
one naming of the lift (``lift`` the reported value, ``lift_std`` its 1-sigma, ``lift_history`` the
estimate over time), the field behind the lift, and exports to pandas and xarray.

A mixin: the run class keeps its data; these methods read ``self.result``, ``self.model`` and
``self.problem``.
"""

from __future__ import annotations

import numpy as np

from wingopt.results.export import field_dataset
from wingopt.results.field import MeanField, mean_field

__all__ = ["RunExports"]


class RunExports:
    """Lift names, the mean field and the pandas/xarray exports of an identification run."""

    @property
    def lift_std(self) -> float | None:
        """1-sigma of :attr:`lift` (N); ``None`` when the estimator gives no band."""
        return self.result.reported_lift[1]

    @property
    def lift_history(self) -> np.ndarray:
        """The lift estimate at every sample (N), ``result.t`` its times (``result.lift``)."""
        return np.asarray(self.result.lift)

    def mean_field(self) -> MeanField:
        """The pressure field behind the reported lift, with its per-point band
        (:mod:`wingopt.results.field`): what ``load.csv`` holds."""
        return mean_field(self.result, self.model)

    def to_dataframe(self):
        """The lift history with its band as a :class:`pandas.DataFrame` (index ``t``, s; the reported
        lift and band in ``.attrs``). Needs pandas (``pip install 'wingopt[data]'``)."""
        return self.result.to_dataframe()

    def to_xarray(self, shape: tuple[int, int] = (57, 29), stride: int = 1):
        """The field over time, the field behind the lift and its band, and the lift history as an
        :class:`xarray.Dataset` (dims ``t``, ``x``, ``y``; units as attributes) on a ``shape = (nx, ny)``
        grid, every ``stride``-th sample. ``ds.to_netcdf(path)`` writes it (``wingopt[data]``)."""
        return field_dataset(self, shape, stride)
