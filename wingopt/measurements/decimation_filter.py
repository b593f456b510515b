"""A DAQ's digital decimation filter on the sensors' signal at the integrator's sub-steps.

A delta-sigma converter samples far faster than it hands over and decimates through a linear-phase
FIR: flat to ``passband fs``, empty from ``stopband fs`` (:class:`~wingopt.measurements.
acquisition.Acquisition`). A release rings in modes above the record's Nyquist frequency; the
converter removes them, where a model's point samples fold them back onto the modes a fit reads
(measured: L1 released from the bubble, 300 Hz, through a delay-compensated 65-tap FIR at 0.45 fs:
-57 % ± 1.2 N, chi-square 1.6, declared or not, where the point-sampled record gives -0.4 %).
:class:`DecimationFilter` runs the declared filter on the record fits' outputs at the integrator's
sub-steps, where those modes are resolved (:meth:`~wingopt.measurements.acquisition.Acquisition.
grid_filter`: the response's inverse transform on that grid, its delay compensated unless
``delay_s`` says the time stamps keep it), and hands over every sample's output. Linear: the same
call filters a prediction and, on the outputs' sensitivities, its Jacobian. The signal before the
record is held at its first value (the converter ran before it), after it at its last.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wingopt.measurements.acquisition import Acquisition, SampleFilter

__all__ = ["DecimationFilter"]


@dataclass(frozen=True, eq=False)
class DecimationFilter:
    """A declared digital decimation filter as a record fit applies it (module docstring)."""

    acquisition: Acquisition
    _at: dict = field(default_factory=dict, repr=False)

    @classmethod
    def of(cls, acquisition: Acquisition | None) -> DecimationFilter | None:
        """The filter of a declared ``acquisition`` (``None``: none, point sampling or an analog one)."""
        if acquisition is None or not acquisition.digital:
            return None
        return cls(acquisition)

    def at(self, step: float, every: int) -> SampleFilter:
        """The filter on a grid of ``step`` seconds, ``every`` grid points a sample (kept)."""
        key = (step, every)
        if key not in self._at:
            self._at[key] = self.acquisition.grid_filter(1.0 / (step * every), 1.0 / step)
        return self._at[key]

    def __call__(self, h: np.ndarray, hd: np.ndarray, step: float, every: int = 1) -> np.ndarray:
        """The record ``(N + 1, ...)`` of the outputs ``h`` on a grid of ``step`` seconds, ``(N every
        + 1, ...)`` (``hd``, their rates, are not needed: the grid resolves the signal)."""
        return self.at(step, every)(h)[::every]
