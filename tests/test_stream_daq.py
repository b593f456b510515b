"""The nonlinear stream models a declared analog DAQ filter (issue 32): the filter's discretisation
against ``scipy.signal.lsim``, point sampling and a digital filter left as they were, and a record
through a Butterworth at fs/3 that the declared stream explains and the undeclared one does not.

Truth: the problem's own FvK membrane (its mesh, full order) released from the bubble under L1,
0.5 s at 1200 Hz, 1 % noise, through the analog filter (``lsim``, settled on the first sample) and
decimated to 300 Hz.
"""

import dataclasses
import functools

import numpy as np
import pytest
import scipy.signal as sig

from wingopt.estimation.registry import resolve
from wingopt.estimation.runners import settings_for
from wingopt.estimation.streaming.nonlinear import NonlinearStreamingEstimator
from wingopt.estimation.streaming.output_filter import (
    AnalogFilter,
    DelayLine,
    FilterStates,
    SensorInput,
    output_filter,
)
from wingopt.measurements.acquisition import Acquisition
from wingopt.membrane import MembraneModel
from wingopt.problem import load_problem
from wingopt.workflows.protocols import simulate_case

RATE, OVERSAMPLE = 300.0, 4
BUTTER = Acquisition("butterworth", order=4, cutoff_hz=RATE / 3)


def _hermite_run(acq: Acquisition, f_hz: float, rate: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """A cosine of ``f_hz`` through the discretised filter at ``rate`` and through ``lsim`` on a grid
    200x finer, both settled on its first value."""
    A, B, C, D = acq.state_space()
    dt, w = 1.0 / rate, 2 * np.pi * f_hz
    states = FilterStates(AnalogFilter.discretise(A, B, C, D, dt))
    none = np.zeros((1, 0))

    def at(k):
        return SensorInput(np.array([np.cos(w * k * dt)]), np.array([-w * np.sin(w * k * dt)]), none, none)

    states.settle(at(0))
    out = [states.output(at(0).h, none)[0][0]]
    for k in range(1, n):
        states.step(at(k - 1), at(k))
        out.append(states.output(at(k).h, none)[0][0])
    fine = dt / 200 * np.arange(200 * (n - 1) + 1)
    _, ref, _ = sig.lsim((A, B[:, None], C[None], D), np.cos(w * fine), fine, X0=-np.linalg.solve(A, B))
    return np.array(out), ref[::200]


@pytest.mark.parametrize("kind", ["butterworth", "bessel"])
def test_the_hermite_discretisation_follows_the_analog_filter(kind):
    acq = Acquisition(kind, order=4, cutoff_hz=RATE / 3)
    A, B, C, D = acq.state_space()
    f = np.array([5.0, 30.0, 50.0, 90.0, 140.0])
    H = np.array([C @ np.linalg.solve(2j * np.pi * fi * np.eye(A.shape[0]) - A, B) + D for fi in f])
    np.testing.assert_allclose(H, acq.response(f, RATE), atol=1e-12)  # the Acquisition's normalisation
    y, ref = _hermite_run(acq, 50.0, RATE, 300)
    # measured: 0.16 % (Butterworth), 0.14 % (Bessel) of the ringing's amplitude; a linear
    # interpolation of the input would be ~9 % off
    assert np.abs(y - ref).max() < 0.005 * np.abs(ref).max()


def test_only_an_analog_filter_gets_states():
    assert output_filter(None, 1 / RATE)[0] is None
    assert output_filter(Acquisition("point"), 1 / RATE)[0] is None
    assert output_filter(Acquisition("delta-sigma"), 1 / RATE)[0] is None
    states, said, warning = output_filter(BUTTER, 1 / RATE)
    assert states is not None and "butterworth" in said and warning is None
    # a delay the time stamps keep: a delay line of 6 samples at 300 Hz
    states, said, warning = output_filter(Acquisition("delta-sigma", delay_s=0.02), 1 / RATE)
    assert isinstance(states, DelayLine) and states.size == 8 and "20 ms delay not compensated" in said
    assert "delayed" in said and warning is None


def _delayed_run(delay: float, f_hz: float, n: int, dtheta: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A cosine of ``f_hz`` at ``RATE`` through a delay line of ``delay`` samples, settled on its first
    value, with one unknown (the cosine's amplitude: ``Jh = h``); and the cosine at ``t - delay dt``
    (the first value before the record). ``dtheta``: an update of the amplitude after the last step."""
    dt, w = 1.0 / RATE, 2 * np.pi * f_hz
    line = DelayLine(delay, dt)

    def at(k):
        h, hd = np.array([np.cos(w * k * dt)]), np.array([-w * np.sin(w * k * dt)])
        return SensorInput(h, hd, h[:, None], hd[:, None])

    line.settle(at(0))
    out = [line.output(at(0).h, at(0).Jh)[0][0]]
    for k in range(1, n):
        line.step(at(k - 1), at(k))
        out.append(line.output(at(k).h, at(k).Jh)[0][0])
    if dtheta:
        line.correct(np.array([dtheta]))
        out[-1] = line.output(at(n - 1).h, at(n - 1).Jh)[0][0]
    t = (np.arange(n) - delay) * dt
    return np.array(out), np.where(t < 0, 1.0, np.cos(w * t))


@pytest.mark.parametrize("delay", [0.0, 3.0, 8.0, 8.4, 2.75])
def test_the_delay_line_hands_over_the_signal_delay_samples_late(delay):
    y, ref = _delayed_run(delay, 50.0, 120)
    # a whole number of samples: exactly the sample that many back; between samples the Hermite
    # interpolant of a 50 Hz cosine at 300 Hz (measured 0.25 % of its amplitude at 0.4 sample; a linear one: 11 %)
    tol = 1e-12 if delay == int(delay) else 4e-3
    np.testing.assert_allclose(y[10:], ref[10:], atol=tol)
    assert np.all(y[: int(delay) + 1] == 1.0)  # before the record: the wing as it was at its start


def test_an_update_moves_the_delayed_record_by_its_sensitivity():
    # the amplitude raised by 5 % after the last sample: the delayed record follows, linearly
    y, ref = _delayed_run(8.4, 50.0, 60, dtheta=0.05)
    y0, _ = _delayed_run(8.4, 50.0, 60)
    assert y[-1] == pytest.approx(1.05 * y0[-1], rel=1e-12)


def test_the_delay_line_moves_its_buffer_with_every_update():
    """Updates between steps move every buffered signal by its sensitivity (the line keeps their sum,
    not moved copies): against a buffer whose entries are each moved, over 40 random steps."""
    rng = np.random.default_rng(3)
    line, naive = DelayLine(5.3, 1 / RATE), []

    def draw():
        return SensorInput(*(rng.normal(size=s) for s in ((4,), (4,), (4, 6), (4, 6))))

    u = draw()
    line.settle(u)
    naive = [SensorInput(u.h, 0 * u.hd, u.Jh, 0 * u.Jhd)] * 6 + [u]
    for _ in range(40):
        u1 = draw()
        line.step(u, u1)
        naive, u = naive[1:] + [u1], u1
        dth = rng.normal(size=6)
        line.correct(dth)
        naive = [SensorInput(v.h + v.Jh @ dth, v.hd + v.Jhd @ dth, v.Jh, v.Jhd) for v in naive]
    ref = DelayLine(5.3, 1 / RATE)
    ref.inputs, ref.moved = naive, np.zeros(6)
    for got, want in zip(line.output(u.h, u.Jh), ref.output(u.h, u.Jh)):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


@functools.cache
def _record(daq: bool):
    problem = load_problem("membrane")
    prestrain = (1.1 * problem.material.prestrain, 0.9 * problem.material.prestrain)
    rec = simulate_case(problem, "L1", 0.01, 7, None, 0.5, truth="fvk", prestrain=prestrain, dt=1 / (OVERSAMPLE * RATE))
    t, y = rec.measurements.t, rec.measurements.values
    if daq:
        A, B, C, D = BUTTER.state_space()
        rest = -np.linalg.solve(A, B)
        y = np.column_stack([sig.lsim((A, B[:, None], C[None], D), s, t, X0=rest * s[0])[1] for s in y.T])
    return problem, t[::OVERSAMPLE], y[::OVERSAMPLE]


def _stream(problem, t, y):
    est = NonlinearStreamingEstimator(
        MembraneModel.from_problem(problem), settings_for(resolve(stream=True), problem=problem)
    )
    chi = []
    for tk, yk in zip(t, y):
        e = est.push(tk, yk)
        if e.phase == "tracking":
            chi.append(e.chi2_per_datum)
    return est, e, float(np.mean(chi))


@pytest.mark.parametrize("acq", [Acquisition("point"), Acquisition("delta-sigma")])
def test_point_sampling_leaves_the_stream_as_it_was_and_a_digital_filter_its_filter(acq):
    """Point sampling declared: bit for bit the undeclared stream. A delta-sigma converter: the
    one-sample filter predicts point samples as before (its passband is flat), the start-up's batch
    fit runs the converter's filter at the sub-steps (it removes the modes above the Nyquist
    frequency): on this point-sampled record, which holds them, the declaration is wrong, the
    start-up fit misfits (chi-square 2.15) and says so, and the answer moves within its band."""
    problem, t, y = _record(False)
    _, plain, chi = _stream(problem, t, y)
    est, e, chi2 = _stream(dataclasses.replace(problem, acquisition=acq), t, y)
    if acq.point:
        assert (e.lift, e.lift_std, chi2) == (plain.lift, plain.lift_std, chi)  # bit for bit
        assert "warnings" not in est.info()
    else:
        assert abs(e.lift - plain.lift) < plain.lift_std and e.lift != plain.lift
        assert any("start-up's batch fit does not fit" in w for w in est.info()["warnings"])
    assert est.daq is None
    assert est.info()["acquisition"].startswith("point" if acq.point else "delta-sigma")


def test_a_declared_butterworth_is_explained_by_the_stream():
    problem, t, y = _record(True)
    undeclared, _, chi0 = _stream(problem, t, y)
    est, _, chi1 = _stream(dataclasses.replace(problem, acquisition=BUTTER), t, y)
    info = est.info()
    assert info["acquisition"] == BUTTER.describe()
    # the filter's lag and gain are in the model: the start-up's fit and the tracking windows explain the record
    start0, start1 = (e.info()["startup_chi2_per_datum"] for e in (undeclared, est))
    print(f"start-up chi2/datum {start0:.2f} -> {start1:.2f}, tracking {chi0:.2f} -> {chi1:.2f}")
    assert start1 < 0.5 * start0
    assert chi1 < chi0 and chi1 < 1.5


@pytest.mark.parametrize("kind", ["delay", "butterworth"])
def test_a_held_stream_keeps_the_daq_filter_states_of_its_last_healthy_state(kind):
    """A failure while tracking restores the last healthy state (:mod:`~wingopt.estimation.streaming.
    recovery`); the DAQ filter's states belong to it: a restore that left them diverged would hand the
    next prediction a filter that ran on the diverged signals."""
    from types import SimpleNamespace

    from wingopt.estimation.streaming.recovery import Recovery

    def u(v):
        h = np.array([v])
        return SensorInput(h, 0 * h, h[:, None], 0 * h[:, None])

    dt = 1 / RATE
    daq = DelayLine(2.5, dt) if kind == "delay" else FilterStates(AnalogFilter.discretise(*BUTTER.state_space(), dt))
    est = SimpleNamespace(phase="tracking", count=3, x=np.zeros(1), G=np.ones((1, 1)), Sigma=np.eye(1), daq=daq)
    est.settings = SimpleNamespace(min_samples=100)  # too few samples for a reset: the restore holds
    daq.settle(u(1.0))
    signal = iter([2.0, 3.0, 1e30])

    def predict():
        v = next(signal)
        est.daq.step(u(v / 2), u(v))
        est.x = np.array([np.nan if v > 1e20 else v])

    est._predict, est._update = predict, lambda y: None
    rec = Recovery(5)
    for _ in range(2):
        rec.step(est, np.zeros(1))
    healthy_out = est.daq.output(np.zeros(1), np.zeros((1, 1)))
    rec.step(est, np.zeros(1))  # the diverged step: restored and held
    assert rec.hold and est.x[0] == 3.0 and rec.events[-1]["phase"] == "tracking"
    for got, kept in zip(est.daq.output(np.zeros(1), np.zeros((1, 1))), healthy_out):
        np.testing.assert_array_equal(got, kept)
