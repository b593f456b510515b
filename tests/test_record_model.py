"""The realistic estimator's building blocks (issue 11): modal Berger model, exact Jacobians, load
model, adequacy test, problem-file keys. Fast; the identification studies are in
test_identify_record.py (slow)."""

import dataclasses

import numpy as np
import pytest

from wingopt.errors import InputError, ProblemFileError
from wingopt.estimation.core.adequacy import assess
from wingopt.estimation.core.load_model import GustAmplitude, LoadShapes
from wingopt.estimation.core.record_problem import ParameterPrior, RecordProblem
from wingopt.membrane import MembraneModel, bubble, forward_model, load_case
from wingopt.membrane.modal.berger import BergerModal
from wingopt.problem import load_problem


@pytest.fixture(scope="module")
def model():
    return MembraneModel.from_problem(load_problem("membrane"))


def _protocol(model, bm, steps, scale=1.0, ex=0.05, ey=0.05, damping=1.0, nonlinear=True):
    pr = model.problem
    f = model.project(load_case("L1", pr.width, pr.height)) * scale
    z0 = model.project(bubble(pr.width, pr.height)) * scale
    forces = np.broadcast_to(bm.input_matrix @ f, (steps, bm.m))
    return bm.simulate(bm.to_modal(z0), np.zeros(bm.m), forces, ex, ey, damping, nonlinear)


def test_modes_diagonalise_both_tension_matrices_and_match_the_linear_model(model):
    bm = BergerModal.build(model, 8)
    # Table 6.2 frequencies at the file's prestrain (spec §6, 25x13).
    assert np.allclose(bm.omega()[:4] / (2 * np.pi), [82.14063341, 103.90059613, 132.44779727, 151.45989864], rtol=1e-8)


def test_small_load_limit_is_the_linear_model(model):
    """At 1e-4 of the protocol's amplitude the Berger model is the linear ZOH to 1e-8 (stretch ~ 1e-8 of eps0)."""
    bm = BergerModal.build(model, model.n)
    pr = model.problem
    scale = 1e-4
    f = model.project(load_case("L1", pr.width, pr.height)) * scale
    z0 = model.project(bubble(pr.width, pr.height)) * scale
    lin = forward_model(model, "linear").run(f, 0.2, z0=z0)
    Z = bm.deflection(_protocol(model, bm, 200, scale))
    assert np.abs(Z - lin.z).max() / np.abs(lin.z).max() < 1e-7
    # and the stretch matters at the protocol's amplitude (tens of percent of the tension)
    Q = _protocol(model, bm, 1)
    sx, sy = bm.stretch(Q[0])
    assert 0.2 < (sx + sy) / 2 / 0.05 < 1.0


def test_integrator_is_second_order_in_the_step(model):
    """Error against 16 sub-steps falls ~4x per halving (measured 2.3e-2, 6.1e-3, 1.5e-3 of the peak)."""
    ref = BergerModal.build(model, 20, substeps=16)
    y_ref = ref.outputs(_protocol(model, ref, 300))
    errs = []
    for sub in (1, 2, 4):
        bm = BergerModal.build(model, 20, substeps=sub)
        errs.append(np.abs(bm.outputs(_protocol(model, bm, 300)) - y_ref).max() / np.abs(y_ref).max())
    assert errs[0] < 0.04
    assert 3.0 < errs[0] / errs[1] < 5.0 and 3.0 < errs[1] / errs[2] < 5.0


def _record_problem(model, gust=None, jacobian="tangent"):
    bm = BergerModal.build(model, 10, substeps=2)
    shapes = LoadShapes.build(model, 6)
    Q = _protocol(model, bm, 59)
    y = bm.outputs(Q)
    y[7, 2] = np.nan  # a missing sample is a missing row
    t = np.arange(60) * 1e-3
    prior = ParameterPrior((0.05, 0.05), ("prestrain_x", "prestrain_y", "damping"))
    x_mean = np.concatenate([Q[0], np.zeros(bm.m)])
    x_std = np.abs(x_mean) + 1e-5
    return RecordProblem(bm, shapes, t, y, np.full(4, 1e-4), prior, x_mean, x_std, gust, True, 6, jacobian)


def test_tangent_jacobian_equals_complex_step(model):
    rp = _record_problem(model, GustAmplitude(knot_s=0.02))
    th = 0.3 * np.random.default_rng(1).standard_normal(rp.dim)
    rd, _, J, _ = rp.residuals(th, jacobian=True)
    rd2, _, J2, _ = dataclasses.replace(rp, jacobian="complex-step").residuals(th, jacobian=True)
    assert rd.size == 60 * 4 - 1
    assert np.abs(rd - rd2).max() < 1e-9 * np.abs(rd).max()
    assert np.abs(J - J2).max() < 1e-9 * np.abs(J2).max()
    # and complex step against a central difference in one parameter direction
    j = rp.slices["par"].start
    e = np.zeros(rp.dim)
    e[j] = 1e-6
    fd = (rp.residuals(th + e)[0] - rp.residuals(th - e)[0]) / 2e-6
    assert np.abs(fd - J[:, j]).max() < 1e-5 * np.abs(J[:, j]).max()


def test_the_sign_flip_mirrors_the_initial_state_and_the_load_with_fewer_state_modes(model):
    """Sign-blind sensors: the fit's mirror image (``x0 -> -x0``, ``c -> -c``) reads the same data.
    With 6 state modes of 10 the flip once broadcast the full prior mean onto the held modes (a
    ValueError on every record fitted against its stated sign, no initial shape declared)."""
    from wingopt.estimation.transient.estimator import _flip

    rp = _record_problem(model)
    m, ms = rp.model.m, rp.state_modes
    assert ms < m
    held = np.r_[0:ms, m : m + ms]
    free = np.zeros(2 * m, bool)
    free[held] = True
    # the modes the unknowns do not hold keep their prior mean: zero when no initial shape is declared
    rp = dataclasses.replace(rp, x0_mean=np.where(free, rp.x0_mean, 0.0))
    th = 0.3 * np.random.default_rng(2).standard_normal(rp.dim)
    a, b = rp.physical(th), rp.physical(_flip(rp, th))
    x0 = lambda p: np.concatenate([p["q0"][0], p["v0"][0]])  # noqa: E731
    assert np.allclose(x0(b), -x0(a), rtol=0, atol=1e-15)
    assert np.allclose(b["c"], -a["c"], rtol=0, atol=1e-15)
    assert np.allclose(rp.residuals(_flip(rp, th))[0], rp.residuals(th)[0], rtol=1e-9, atol=1e-12)


def test_load_shapes_and_gust_basis(model):
    shapes = LoadShapes.build(model, 5)
    G = shapes.shapes.T @ (model.gram @ shapes.shapes)
    assert np.allclose(G, np.eye(5), atol=1e-10)
    assert shapes.lift_row[0] > 0 and np.all(np.diff(shapes.prior_std) <= 0)
    gust = GustAmplitude(knot_s=0.01)
    t = np.arange(101) * 1e-3
    H = gust.basis(t)
    assert H.shape == (101, 11) and np.allclose(H.sum(axis=1), 1.0)
    assert np.allclose(H @ np.linspace(0, 1, 11), t / 0.1)  # linear functions exactly
    with pytest.raises(InputError, match="knot_s"):
        GustAmplitude(knot_s=0.0)


def test_adequacy_flags_a_misfit_and_widens_the_band():
    rng = np.random.default_rng(0)
    t = np.arange(1000) * 1e-3
    white = rng.standard_normal((1000, 4))
    ok = assess(t, white, 10.0)
    assert ok.adequate and ok.inflation == 1.0 and abs(ok.chi2_per_datum - 1) < 0.06
    bad = white.copy()
    bad[:80] += 6.0  # an unexplained start: 80 ms that do not fit
    ad = assess(t, bad, 10.0)
    assert not ad.adequate
    assert ad.bad_segments[0][0] == 0.0 and ad.bad_segments[-1][1] < 0.1
    # widened by the worst misfit segment (~37 per datum), not the diluted overall value (~3)
    assert ad.inflation == pytest.approx(np.sqrt(max(ad.segment_chi2_per_datum))) and ad.inflation > 5


def test_problem_file_free_parameters(tmp_path):
    src = (load_problem("membrane").source, None)[0]
    text = open(src).read()
    good = tmp_path / "p.toml"
    good.write_text(text + 'free_parameters = ["prestrain_x", "damping"]\nprestrain_prior_rel = 0.1\n')
    ident = load_problem(str(good)).identification
    assert ident.free_parameters == ("prestrain_x", "damping") and ident.prestrain_prior_rel == 0.1
    bad = tmp_path / "q.toml"
    bad.write_text(text + 'free_parameters = ["prestrain"]\n')
    with pytest.raises(ProblemFileError, match="free_parameters"):
        load_problem(str(bad))
    with pytest.raises(InputError, match="free_parameters"):
        ParameterPrior((0.05, 0.05), ("tension",))
