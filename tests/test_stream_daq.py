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
    # a delay the time stamps keep: the start-up fit models it, the one-sample filter does not, and says so
    states, said, warning = output_filter(Acquisition("delta-sigma", delay_s=0.02), 1 / RATE)
    assert states is None and "20 ms delay not compensated" in said and "its one-sample filter does not" in warning


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
