"""A DAQ's analog low-pass on the sensors' continuous signal: discretised exactly, run causally.

A record handed over by an analog anti-aliasing filter (a declared ``butterworth`` or ``bessel``
:class:`~wingopt.measurements.acquisition.Acquisition`) is the filter's output on the sensors'
*continuous* signal, sampled. Per sensor the filter's state space ``(A, B, C, D)``
(:meth:`~wingopt.measurements.acquisition.Acquisition.state_space`) runs on ``h(t) = q^T C_i q``;
between two grid points the input is the cubic Hermite interpolant of ``h`` and its derivative
``dh/dt = 2 q^T C_i v`` at both ends, so

    w_{k+1} = Ad w_k + b0 h_k + b1 dt h'_k + b2 h_{k+1} + b3 dt h'_{k+1},   y_k = C w_k + D h_k,

``Ad = exp(A dt)`` and ``b_j = int_0^dt exp(A (dt - s)) B phi_j(s / dt) ds`` for the four Hermite
basis functions ``phi_j`` (:class:`AnalogFilter`, computed once by Gauss–Legendre quadrature). The
stream carries these states one sample at a time
(:mod:`wingopt.estimation.streaming.output_filter`); a record fit runs them over the whole record
(:class:`CausalFilter`).

The grid must resolve the signal: a release rings in modes above the Nyquist frequency that the
filter attenuates, not removes, and the interpolant at the sample rate misreads them (a unit ringing
at 200 Hz sampled at 300 Hz through a 4th-order Butterworth at 100 Hz: 0.19 off the filter's output,
whose true amplitude is 0.06; at 250 Hz 0.54 for 0.03). On the integrator's sub-steps (e.g. 1200 Hz)
the same errors are 5e-4 and 3e-3 of the amplitude at the record's start, 1e-4 after a few samples
(``tests/test_transient_daq_causal.py``). :class:`CausalFilter` therefore runs on the sub-steps and
hands over every ``every``-th output. The filter is settled on the first input (a wing at rest or in
equilibrium: the DAQ ran before the record). Linear: the same call filters a prediction and, on the
inputs' sensitivities, its exact Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

__all__ = ["AnalogFilter", "CausalFilter", "NODES", "hermite_basis"]

NODES = 16
"""Gauss–Legendre nodes of the input matrices' quadrature (the integrand is smooth: exact to rounding)."""

_ANALOG = ("butterworth", "bessel")


def hermite_basis(tau: np.ndarray) -> np.ndarray:
    """The cubic Hermite basis ``(4, n)`` at ``tau`` in [0, 1]: value and slope at 0, value and slope at 1."""
    t2, t3 = tau**2, tau**3
    return np.array([2 * t3 - 3 * t2 + 1, t3 - 2 * t2 + tau, 3 * t2 - 2 * t3, t3 - t2])


@dataclass(frozen=True, eq=False)
class AnalogFilter:
    """An analog filter discretised at the sample period ``dt`` for a Hermite-interpolated input.

    ``Ad`` ``(n, n)``: the states' map over a sample; ``Bh`` ``(4, n)``: the input's, per
    ``(h_k, h'_k, h_{k+1}, h'_{k+1})`` (the slopes' ``dt`` folded in); ``C``, ``D``: the output;
    ``rest`` ``(n,)``: the states settled on a unit input (``-A^-1 B``)."""

    Ad: np.ndarray
    Bh: np.ndarray
    C: np.ndarray
    D: float
    rest: np.ndarray

    @classmethod
    def discretise(cls, A: np.ndarray, B: np.ndarray, C: np.ndarray, D: float, dt: float) -> AnalogFilter:
        """``(A, B, C, D)`` continuous, at the sample period ``dt`` (s)."""
        x, wq = np.polynomial.legendre.leggauss(NODES)
        tau, wq = 0.5 * (x + 1.0), 0.5 * wq
        kernel = np.array([sla.expm(A * (dt * (1.0 - s))) @ B for s in tau])  # (NODES, n)
        Bh = dt * (hermite_basis(tau) * wq) @ kernel
        Bh[1::2] *= dt  # the slopes enter as dt h'
        return cls(sla.expm(A * dt), Bh, np.asarray(C, float), float(D), -np.linalg.solve(A, B))


@dataclass(frozen=True, eq=False)
class CausalFilter:
    """A declared analog filter run over a whole record's Hermite-interpolated signal (module
    docstring): what a record fit predicts of a record handed over by it.

    ``A, B, C, D``: the filter's continuous state space; discretised once per grid step."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: float
    _at: dict = field(default_factory=dict, repr=False)

    @classmethod
    def of(cls, acquisition) -> CausalFilter | None:
        """The filter of a declared ``acquisition`` (``None``: none, point sampling or a digital
        filter: :class:`~wingopt.measurements.decimation_filter.DecimationFilter`)."""
        if acquisition is None or acquisition.kind not in _ANALOG:
            return None
        return cls(*acquisition.state_space())

    def at(self, step: float) -> AnalogFilter:
        """The filter discretised on a grid of ``step`` seconds (kept)."""
        if step not in self._at:
            self._at[step] = AnalogFilter.discretise(self.A, self.B, self.C, self.D, step)
        return self._at[step]

    def __call__(self, h: np.ndarray, hd: np.ndarray, step: float, every: int = 1) -> np.ndarray:
        """The filter's outputs at every ``every``-th grid point, ``(N + 1, ...)``, of the input's
        values ``h`` and time derivatives ``hd`` on a grid of ``step`` seconds, ``(N every + 1,
        ...)`` (any trailing axes: sensors, and unknowns for a Jacobian), settled on ``h[0]``."""
        f = self.at(step)
        rows = h.shape[0]
        N = (rows - 1) // every
        if N * every + 1 != rows or hd.shape != h.shape:
            raise ValueError(f"CausalFilter: {rows} grid points are not {every} per sample (or hd's shape differs)")
        x, xd = h.reshape(rows, -1), hd.reshape(rows, -1)
        # a sample's drive is the sum over its grid steps of Ad^(every-1-s) times the step's input
        G = np.stack([np.linalg.matrix_power(f.Ad, every - 1 - s) @ f.Bh.T for s in range(every)])  # (S, n, 4)
        u = np.stack([x[:-1], xd[:-1], x[1:], xd[1:]], axis=-1)  # (N S, X, 4)
        u = u.reshape(N, every, x.shape[1], 4).transpose(0, 2, 1, 3).reshape(N, x.shape[1], every * 4)
        drive = u @ G.transpose(0, 2, 1).reshape(every * 4, -1)  # (N, X, n)
        AdS = np.linalg.matrix_power(f.Ad, every).T
        W = np.empty((N + 1,) + drive.shape[1:], drive.dtype)
        W[0] = x[0][:, None] * f.rest
        for k in range(N):
            W[k + 1] = W[k] @ AdS + drive[k]
        y = W @ f.C + f.D * x[::every]
        return y.reshape((N + 1,) + h.shape[1:])
