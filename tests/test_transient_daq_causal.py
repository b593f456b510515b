"""The batch record fits model a declared analog DAQ filter causally, from the trajectory (issue 32).

:class:`~wingopt.measurements.analog_filter.CausalFilter` runs the filter's state space on the
sensors' Hermite interpolant (values ``q^T C q``, slopes ``2 q^T C v``) at the integrator's
sub-steps: checked here are the modal velocities the kernels hand over (against differences of the
displacements), the prediction (against ``scipy.signal.lsim`` of the same trajectory's sensor
signals on a grid 16x finer), the Jacobian (finite differences and the complex step), and that
everything else (no filter, point, digital, the sample filter) gives the numbers it gave before
(``tests/data/record_problem_daq_reference.npz``, written by the code before the change:
``python tests/test_transient_daq_causal.py PATH`` writes it again).
"""

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.signal as sig

from wingopt.estimation.core.load_model import GustAmplitude, LoadShapes
from wingopt.estimation.core.record_problem import ParameterPrior, RecordProblem
from wingopt.measurements.acquisition import Acquisition
from wingopt.measurements.analog_filter import CausalFilter
from wingopt.membrane import MembraneModel, bubble, load_case
from wingopt.membrane.forward import modal_model
from wingopt.problem import load_problem

RATE, N = 300.0, 40
BUTTER = Acquisition("butterworth", order=4, cutoff_hz=RATE / 3)
DELTA_SIGMA = Acquisition("delta-sigma")
REFERENCE = Path(__file__).parent / "data" / "record_problem_daq_reference.npz"


def problems() -> dict[str, RecordProblem]:
    """L1 from the bubble, 40 samples at 300 Hz (modes to ~330 Hz): Berger (gust knots) and FvK,
    without a filter, with the sample filter, and (Berger) by the complex step."""
    model = MembraneModel.from_problem(load_problem("membrane"))
    pr = model.problem
    out = {}
    for physics, modes, sub in (("berger", 10, 3), ("fvk", 12, 4)):
        bm = modal_model(model, physics, modes, 1.0 / RATE, sub, cubic_modes=6)
        shapes = LoadShapes.build(model, 6)
        f = model.project(load_case("L1", pr.width, pr.height))
        z0 = model.project(bubble(pr.width, pr.height))
        forces = np.broadcast_to(bm.input_matrix @ f, (N - 1, bm.m))
        Q = bm.simulate(bm.to_modal(z0), np.zeros(bm.m), forces, 0.05, 0.05, 1.0)
        y = bm.outputs(Q) * (1 + 0.01 * np.random.default_rng(3).standard_normal((N, bm.p)))
        y[7, 2] = np.nan
        prior = ParameterPrior((0.05, 0.05), ("prestrain_x", "prestrain_y", "damping"))
        x_mean = np.concatenate([Q[0], np.zeros(bm.m)])
        gust = GustAmplitude(knot_s=0.03) if physics == "berger" else None
        rp = RecordProblem(
            bm, shapes, np.arange(N) / RATE, y, np.full(bm.p, 1e-4), prior, x_mean, np.abs(x_mean) + 1e-5, gust, True, 6
        )
        out[f"{physics}_none"] = rp
        out[f"{physics}_sample"] = dataclasses.replace(rp, daq=BUTTER.sample_filter(RATE))
        if physics == "berger":
            out[f"{physics}_none_cs"] = dataclasses.replace(rp, jacobian="complex-step")
    return out


def _theta(rp: RecordProblem) -> np.ndarray:
    return 0.3 * np.random.default_rng(1).standard_normal(rp.dim)


def _arrays(rp: RecordProblem) -> dict[str, np.ndarray]:
    th = _theta(rp)
    r0, p0 = rp.residuals(th)
    r1, _, J, _ = rp.residuals(th, jacobian=True)
    Q, pred = rp.predicted(th)
    return dict(r0=r0, p0=p0, r1=r1, J=J, Q=Q, pred=pred)


@pytest.fixture(scope="module")
def cases():
    return problems()


def _causal(rp: RecordProblem) -> RecordProblem:
    return dataclasses.replace(rp, daq=CausalFilter.of(BUTTER))


def test_without_a_causal_filter_the_numbers_are_those_before(cases):
    """No filter, the sample filter, the complex step: every array bit for bit as before; point
    sampling and a digital filter have no causal filter (the record fits predict point samples)."""
    ref = np.load(REFERENCE)
    for name, rp in cases.items():
        for key, value in _arrays(rp).items():
            assert np.array_equal(value, ref[f"{name}/{key}"], equal_nan=True), f"{name}/{key}"
    assert CausalFilter.of(None) is None and CausalFilter.of(Acquisition("point")) is None
    assert CausalFilter.of(Acquisition("delta-sigma")) is None and CausalFilter.of(Acquisition("fir")) is None


@pytest.mark.parametrize("physics", ["berger", "fvk"])
def test_the_velocities_are_the_displacements_rate(cases, physics):
    """At the sub-steps: ``V`` is the central difference of ``Q`` to the difference's error, second
    order in the step (measured 1.4e-3 and 3.7e-4 of the largest velocity at 8x and 16x the
    sub-steps: Berger), the tangent loop's ``Q, V`` are the plain loop's, and the samples (every
    ``substeps``-th row) are the plain trajectory's, bit for bit."""
    rp = cases[f"{physics}_none"]
    bm, th = rp.model, _theta(rp)
    errors = []
    for k in (8, 16):
        fine = dataclasses.replace(bm, substeps=k * bm.substeps)
        Q, V = (X[:, 0] for X in dataclasses.replace(rp, model=fine).trajectory(th[None], every_substep=True))
        central = (Q[2:] - Q[:-2]) / (2 * fine.dt / fine.substeps)
        errors.append(np.abs(central - V[1:-1]).max() / np.abs(V).max())
    assert errors[0] < 2e-3 and 3.0 < errors[0] / errors[1] < 5.0
    S = bm.substeps
    Qs, Vs = (X[:, 0] for X in rp.trajectory(th[None], every_substep=True))
    assert np.array_equal(Qs[::S], rp.trajectory(th[None])[:, 0])
    Qt, _, Vt, _ = _causal(rp)._tangent(th)
    assert Qt.shape == Qs.shape and np.abs(Qt - Qs).max() < 1e-12 * np.abs(Qs).max()
    assert np.abs(Vt - Vs).max() < 1e-12 * np.abs(Vs).max()


def test_the_causal_prediction_is_the_analog_filter_on_the_signal(cases):
    """The linear membrane (the integrator exact: the same trajectory at any sub-step; modes to 223
    Hz, above the Nyquist frequency) from the bubble, its sensors' signal on a grid 16x finer through
    ``lsim`` (settled on the first value), sampled: the causal filter on the 3 sub-steps per sample
    is within 5e-4 of the signal (measured 2.3e-4; 6e-6 at 7 sub-steps, the transient fit's at 300
    Hz). On the samples alone the Hermite interpolant misreads the modes above Nyquist (measured
    0.11 at the release), and so does the sample filter's band-limited reconstruction (0.17)."""
    rp = dataclasses.replace(cases["berger_none"], nonlinear=False, gust=None)
    bm, th = rp.model, _theta(rp)
    fine = dataclasses.replace(rp, model=dataclasses.replace(bm, substeps=16 * bm.substeps))
    Q = fine.trajectory(th[None], every_substep=True)[0][:, 0]
    h = bm.outputs(Q)
    A, B, C, D = BUTTER.state_space()
    t = np.arange(h.shape[0]) * bm.dt / fine.model.substeps
    rest = -np.linalg.solve(A, B)
    ref = np.stack(
        [sig.lsim((A, B[:, None], C[None], D), h[:, i], t, X0=rest * h[0, i])[1] for i in range(bm.p)], axis=1
    )[:: fine.model.substeps]
    scale = np.abs(ref).max()
    _, causal = _causal(rp).predicted(th)
    assert np.abs(causal - ref).max() < 5e-4 * scale
    _, at_samples = _causal(dataclasses.replace(rp, model=dataclasses.replace(bm, substeps=1))).predicted(th)
    _, band_limited = dataclasses.replace(rp, daq=BUTTER.sample_filter(RATE)).predicted(th)
    assert np.abs(at_samples - ref).max() > 0.05 * scale and np.abs(band_limited - ref).max() > 0.1 * scale


@pytest.mark.parametrize("daq", ["analog", "converter"])
@pytest.mark.parametrize("physics", ["berger", "fvk"])
def test_the_sub_step_filters_jacobian_is_exact(cases, physics, daq):
    """Against central differences in every unknown (rel. 1e-6 of the Jacobian; measured 2e-10)
    and the complex step (1e-12); the residuals with and without the Jacobian agree exactly. The
    analog filter run causally, a delta-sigma converter's as its response on the sub-steps."""
    from wingopt.measurements.decimation_filter import DecimationFilter

    rp = cases[f"{physics}_none"]
    rp = _causal(rp) if daq == "analog" else dataclasses.replace(rp, daq=DecimationFilter.of(DELTA_SIGMA))
    th = _theta(rp)
    r, _, J, _ = rp.residuals(th, jacobian=True)
    assert np.array_equal(r, rp.residuals(th)[0])
    eye = 1e-6 * np.eye(rp.dim)
    fd = np.stack([(rp.residuals(th + e)[0] - rp.residuals(th - e)[0]) / 2e-6 for e in eye], axis=1)
    assert np.abs(fd - J).max() < 1e-6 * np.abs(J).max()
    rc, _, Jc, _ = dataclasses.replace(rp, jacobian="complex-step").residuals(th, jacobian=True)
    assert np.abs(Jc - J).max() < 1e-12 * np.abs(J).max() and np.abs(rc - r).max() < 1e-12 * np.abs(r).max()


@pytest.mark.parametrize("daq", ["none", "sample", "causal", "converter"])
def test_a_batchs_outputs_are_each_members_prediction(cases, daq):
    """``RecordProblem.outputs`` (a start-up scan's ranking on a filtered record) is ``predicted``
    of each member of the batch."""
    rp = cases["berger_none"]
    rp = _causal(rp) if daq == "causal" else cases["berger_sample"] if daq == "sample" else rp
    if daq == "converter":
        from wingopt.measurements.decimation_filter import DecimationFilter

        rp = dataclasses.replace(rp, daq=DecimationFilter.of(DELTA_SIGMA))
    th = np.stack([_theta(rp), -0.5 * _theta(rp)])
    out = rp.outputs(th)
    for b in range(2):
        assert np.abs(out[:, b] - rp.predicted(th[b])[1]).max() < 1e-12 * np.abs(out).max()


def test_the_causal_filter_settles_on_the_first_value_and_is_linear():
    f = CausalFilter.of(BUTTER)
    h = np.full((13, 2), 3.5)
    assert np.allclose(f(h, np.zeros_like(h), 1 / 1200, 4), 3.5, atol=1e-12)
    rng = np.random.default_rng(0)
    x, xd, y, yd = rng.normal(size=(4, 13, 3, 2))
    assert np.allclose(f(x + 2 * y, xd + 2 * yd, 1e-3, 3), f(x, xd, 1e-3, 3) + 2 * f(y, yd, 1e-3, 3), atol=1e-13)
    with pytest.raises(ValueError):
        f(x[:12], xd[:12], 1e-3, 3)


if __name__ == "__main__":  # the reference of the numbers without a causal filter
    np.savez_compressed(sys.argv[1], **{f"{n}/{k}": v for n, rp in problems().items() for k, v in _arrays(rp).items()})


# -- a digital decimation filter at the sub-steps ----------------------------------------------------------------


def test_the_decimation_filter_passes_the_band_and_removes_what_the_converter_removes():
    """On a 7x grid (a 300 Hz record's sub-steps): a 90 Hz sine (0.3 fs) passes as it is, a 210 Hz
    one (0.7 fs, above the stopband; point samples fold it onto 90 Hz) is gone; a declared delay
    shifts the record."""
    from wingopt.measurements.decimation_filter import DecimationFilter

    f, S = DecimationFilter.of(DELTA_SIGMA), 7
    assert DecimationFilter.of(BUTTER) is None and DecimationFilter.of(None) is None
    t = np.arange(300 * S + 1) / (RATE * S)
    ts = t[::S]

    def run(freq, filt=f):
        x = np.sin(2 * np.pi * freq * t)[:, None]
        return filt(x, np.zeros_like(x), 1 / (RATE * S), S)[:, 0]

    inner = slice(40, -40)
    assert np.abs(run(90.0)[inner] - np.sin(2 * np.pi * 90.0 * ts)[inner]).max() < 2e-3
    assert np.abs(run(210.0)[inner]).max() < 2e-3  # point samples of it: amplitude 1 at 90 Hz
    late = DecimationFilter.of(Acquisition("delta-sigma", delay_s=5 / RATE))
    assert np.abs(run(30.0, late)[inner] - np.sin(2 * np.pi * 30.0 * (ts - 5 / RATE))[inner]).max() < 2e-3
