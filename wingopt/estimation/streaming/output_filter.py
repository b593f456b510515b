"""The DAQ's analog anti-aliasing filter inside the nonlinear stream: its states, one sample at a time.

A record handed over by an analog low-pass (a declared ``butterworth`` or ``bessel``
:class:`~wingopt.measurements.acquisition.Acquisition`) is not the membrane's outputs at the sample
times: a 4th-order Butterworth at fs/3 passes a 50 Hz ringing at 300 Hz at 0.91 of its amplitude,
1.9 ms late. The batch fits run the filter over their whole predicted record at the integrator's
sub-steps (:class:`~wingopt.measurements.analog_filter.CausalFilter`; the stream's start-up fit is
one of them); a filter that goes one sample at a time carries the analog filter's own states at the
sample rate instead (modes above the Nyquist frequency, which ring at a release, are followed less
well there: the start-up fit has taken the release). Per sensor ``i`` the filter's continuous state
space ``(A, B, C, D)`` (:meth:`~wingopt.measurements.acquisition.Acquisition.state_space`) runs on
the sensor's signal ``h_i(t) = q^T C_i q``; the record is ``y_k = C w_k + D h(x_k)``.

Between two samples the input is the cubic Hermite interpolant of ``h`` and its derivative
``dh/dt = 2 q^T C_i v`` at both ends (the modal velocities are in the state): a linear
interpolation attenuates a 50 Hz ringing at 300 Hz by about 9 %, the Hermite one follows it to
well within 1 % (``tests/test_stream_daq.py`` checks against ``scipy.signal.lsim``). So

    w_{k+1} = Ad w_k + b0 h_k + b1 dt h'_k + b2 h_{k+1} + b3 dt h'_{k+1},

``Ad = exp(A dt)`` and ``b_j = int_0^dt exp(A (dt - s)) B phi_j(s / dt) ds`` for the four Hermite
basis functions ``phi_j``, computed once by Gauss–Legendre quadrature
(:class:`~wingopt.measurements.analog_filter.AnalogFilter`, which the batch fits share). The map is
linear in the input: the states' sensitivity to the stream's unknowns, ``dW = dw / dtheta``, goes
on with the same matrices from the input's (``dh / dtheta = 2 C_i q dq/dtheta``, and the
derivative's), exact, as ``G`` does; the measurement Jacobian is ``C dW + D H G`` and an update
``dtheta`` moves the states by ``dW dtheta``. At the start the states sit settled on the first
predicted output (a wing at rest or in equilibrium: the DAQ ran before the record).

A digital decimation filter (``fir``, ``delta-sigma``) is flat and delay-compensated in its
passband: the one-sample filter predicts point samples, as for ``point`` (:func:`output_filter`
returns ``None``), while the start-up's batch fit runs the filter at the sub-steps
(:class:`~wingopt.measurements.decimation_filter.DecimationFilter`: it removes the modes above the
Nyquist frequency that ring at a release). A declared delay the time stamps keep (``delay_s``:
a converter's group delay, 8 samples for the fuzz's 65-tap FIR) is a delay line (:class:`DelayLine`):
the record at ``t_k`` is the sensors' signal at ``t_k - delay_s``, the cubic Hermite interpolant of
the buffered signals and rates of the two samples around it, their sensitivities buffered with
them and moved by each update as the filter's states are.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from wingopt.measurements.analog_filter import AnalogFilter, hermite_basis

__all__ = ["AnalogFilter", "DelayLine", "FilterStates", "SensorInput", "output_filter", "sensor_input"]

_MODELLED = ("butterworth", "bessel")


class SensorInput(NamedTuple):
    """The filter's input at one sample: ``h`` ``(p,)``, its time derivative ``hd``, and their
    sensitivities to the unknowns ``Jh``, ``Jhd`` ``(p, d)``."""

    h: np.ndarray
    hd: np.ndarray
    Jh: np.ndarray
    Jhd: np.ndarray


def sensor_input(sensors: np.ndarray, q: np.ndarray, v: np.ndarray, dQ: np.ndarray, dV: np.ndarray) -> SensorInput:
    """The sensors' signals ``h_i = q^T C_i q`` and ``dh_i/dt = 2 q^T C_i v`` of the modal state
    ``(q, v)`` and their sensitivities from the state's ``dQ``, ``dV`` ``(d, m)`` (rows: unknowns);
    ``sensors``: the ``C_i`` ``(p, m, m)``, symmetric."""
    Cq, Cv = sensors @ q, sensors @ v
    return SensorInput(Cq @ q, 2.0 * (Cq @ v), 2.0 * (Cq @ dQ.T), 2.0 * (Cv @ dQ.T + Cq @ dV.T))


class FilterStates:
    """The filter's states of every sensor, ``w`` ``(p, n)``, and their sensitivity ``dW`` ``(p, n, d)``."""

    def __init__(self, f: AnalogFilter) -> None:
        self.f = f
        self.w: np.ndarray | None = None
        self.dW: np.ndarray | None = None

    def settle(self, u: SensorInput) -> None:
        """The states at rest on the input ``u`` (its value; a wing at rest or in equilibrium)."""
        self.w = np.outer(u.h, self.f.rest)
        self.dW = self.f.rest[None, :, None] * u.Jh[:, None, :]

    def step(self, u0: SensorInput, u1: SensorInput) -> None:
        """One sample on, the input Hermite-interpolated between ``u0`` and ``u1``."""
        Ad, b = self.f.Ad, self.f.Bh
        self.w = self.w @ Ad.T + np.outer(u0.h, b[0]) + np.outer(u0.hd, b[1]) + np.outer(u1.h, b[2])
        self.w += np.outer(u1.hd, b[3])
        dW = np.einsum("ij,pjd->pid", Ad, self.dW)
        for bj, J in zip(b, (u0.Jh, u0.Jhd, u1.Jh, u1.Jhd)):
            dW += bj[None, :, None] * J[:, None, :]
        self.dW = dW

    def output(self, h: np.ndarray, Jh: np.ndarray, ok: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The predicted record ``C w + D h`` and its sensitivity ``C dW + D Jh`` of the sensors
        ``ok`` (a mask; ``None``: all), ``h`` and ``Jh`` already of those sensors only."""
        w, dW = (self.w, self.dW) if ok is None else (self.w[ok], self.dW[ok])
        return w @ self.f.C + self.f.D * h, np.einsum("j,pjd->pd", self.f.C, dW) + self.f.D * Jh

    def correct(self, dtheta: np.ndarray) -> None:
        """The measurement update's step ``dtheta`` of the unknowns, carried to the states."""
        self.w += self.dW @ dtheta

    def snapshot(self) -> tuple[np.ndarray, np.ndarray]:
        """The states as they are (what a stream's recovery holds with the last healthy state)."""
        return self.w.copy(), self.dW.copy()

    def restore(self, snapshot: tuple[np.ndarray, np.ndarray]) -> None:
        self.w, self.dW = (a.copy() for a in snapshot)


class DelayLine:
    """The record ``delay`` samples behind the sensors' signals (a converter's group delay the time
    stamps keep): the last ``floor(delay) + 2`` samples' inputs (:class:`SensorInput`) buffered, the
    output the cubic Hermite interpolant at ``t_k - delay dt``. The same steps as
    :class:`FilterStates` (``settle``, ``step``, ``output``, ``correct``); the buffered
    sensitivities are to the stream's unknowns as ``G`` is, so an update moves the buffer.

    An update is linear in the buffered signals: instead of moving every entry, the updates since
    the buffer settled are summed (``moved``) and each entry is kept less its sensitivity times the
    sum at its entry, so an update and a step cost the same whatever the delay's length."""

    def __init__(self, delay: float, dt: float) -> None:
        whole = int(np.floor(delay + 1e-9))
        s = 1.0 - (delay - whole)  # the point's place between the older (0) and the newer (1) sample
        self.size, self.dt = whole + 2, dt
        # Hermite basis at s: value at the older and the newer sample, and their rates (times dt)
        self.weights = tuple(float(w) for w in hermite_basis(np.asarray(s)))
        self.inputs: list[SensorInput] = []
        self.moved = np.zeros(0)

    def settle(self, u: SensorInput) -> None:
        """The buffer of a wing at rest or in equilibrium before the record: ``u``'s signal, no rate."""
        zero = np.zeros_like(u.hd)
        self.inputs = [SensorInput(u.h, zero, u.Jh, np.zeros_like(u.Jh))] * (self.size - 1) + [u]
        self.moved = np.zeros(u.Jh.shape[1])

    def step(self, u0: SensorInput, u1: SensorInput) -> None:
        """One sample on: ``u1`` joins the buffer, the oldest leaves (``u0`` is in it already)."""
        kept = SensorInput(u1.h - u1.Jh @ self.moved, u1.hd - u1.Jhd @ self.moved, u1.Jh, u1.Jhd)
        self.inputs = self.inputs[1:] + [kept]

    def output(self, h: np.ndarray, Jh: np.ndarray, ok: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The record and its sensitivity, of the sensors ``ok`` (``None``: all); ``h``, ``Jh`` (the
        newest sample's) are not needed: the buffer holds them."""
        older, newer = self.inputs[0], self.inputs[1]
        w0, w1, w2, w3 = self.weights
        sel = slice(None) if ok is None else ok
        J = w0 * older.Jh + w1 * self.dt * older.Jhd + w2 * newer.Jh + w3 * self.dt * newer.Jhd
        y = w0 * older.h + w1 * self.dt * older.hd + w2 * newer.h + w3 * self.dt * newer.hd + J @ self.moved
        return y[sel], J[sel]

    def correct(self, dtheta: np.ndarray) -> None:
        """The measurement update's step ``dtheta`` carried to the buffered signals."""
        self.moved = self.moved + dtheta

    def snapshot(self) -> tuple[list[SensorInput], np.ndarray]:
        """The buffer as it is (its entries are replaced, never changed in place)."""
        return list(self.inputs), self.moved.copy()

    def restore(self, snapshot: tuple[list[SensorInput], np.ndarray]) -> None:
        self.inputs, self.moved = list(snapshot[0]), snapshot[1].copy()


def output_filter(acquisition, dt: float) -> tuple[FilterStates | DelayLine | None, str, str | None]:
    """What a stream sampled every ``dt`` s models of the declared ``acquisition``: the filter's
    states or a delay line (``None``: it predicts point samples), a line saying what it modelled, and a warning
    where a declared filter is one it cannot model."""
    if acquisition is None:
        return None, "point sampling (none declared)", None
    said = acquisition.describe()
    if acquisition.kind in _MODELLED:
        return FilterStates(AnalogFilter.discretise(*acquisition.state_space(), dt)), said, None
    if acquisition.point:
        return None, said, None
    if acquisition.digital and acquisition.delay_s:
        return DelayLine(acquisition.delay_s / dt, dt), f"{said}: point samples of its passband, delayed", None
    if acquisition.digital:  # flat and delay-compensated in its passband: point sampling (module docstring)
        return None, f"{said}: point samples of its passband", None
    warning = (
        f"the declared acquisition ({said}) is not one the stream can model: it predicts point samples, "
        "and the filter's gain and lag show as a misfit"
    )
    return None, said, warning
