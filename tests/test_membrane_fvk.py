"""Föppl–von Kármán membrane: consistency, small-load limit, exact large-deflection limit, convergence."""

import dataclasses

import numpy as np
import pytest
from _alpha import AlphaSettings, LinearStructure
from _alpha import integrate as alpha_integrate

from wingopt.errors import InputError
from wingopt.fe import DX, DY, assemble, load_vector, separable
from wingopt.membrane import Gust, MembraneModel, MembraneParameters, RecordProtocol, bubble, load_case, simulate_truth
from wingopt.membrane.forward import forward_model
from wingopt.membrane.full import FvKMembrane, integrate
from wingopt.membrane.modal import FvKModal
from wingopt.problem import load_problem
from wingopt.workflows.protocols import simulate_case


def exact_hold(model, f, t_end, z0, dt=1e-3):
    """The linear model's exact zero-order hold (the dynamics layer's modal discretisation)."""
    modal = model.modal()
    steps = int(round(t_end / dt))
    Q, _ = modal.discretize(dt).simulate(
        modal.to_modal(z0, model.mass), np.zeros(modal.count), np.broadcast_to(f, (steps, model.n))
    )
    return Q @ modal.shapes.T


@pytest.fixture(scope="module")
def problem():
    return load_problem("membrane")


@pytest.fixture(scope="module")
def fvk(problem):
    return FvKMembrane(problem)


def _l1(problem, model):
    return model.linear.project(load_case("L1", problem.width, problem.height))


def test_point_operators_match_the_assembly_loop(fvk):
    """Gx, Gy from the point operators equal wingopt.fe.assemble; K_T0 is the linear model's K_T."""
    gx = assemble(fvk.space, separable((1.0, DX, DX)), method="cells")
    gy = assemble(fvk.space, separable((1.0, DY, DY)), method="cells")
    assert abs(fvk.gx - gx).max() <= 1e-12 * abs(gx).max()
    assert abs(fvk.gy - gy).max() <= 1e-12 * abs(gy).max()
    K = fvk.linear.stiffness
    assert abs(fvk.linear_stiffness - K).max() <= 1e-12 * abs(K).max()


def test_residual_is_the_energy_gradient_and_tangent_its_derivative(problem):
    m = FvKMembrane(problem, (13, 7), MembraneParameters(0.05, 0.03))
    rng = np.random.default_rng(1)
    n = m.n
    x = np.concatenate([rng.standard_normal(n) * 2e-3, rng.standard_normal(2 * n) * 1e-4])
    d = rng.standard_normal(3 * n)
    split = lambda x: (x[:n], x[n : 2 * n], x[2 * n :])  # noqa: E731
    R = lambda x: np.concatenate(m.residual(*split(x)))  # noqa: E731
    h = 1e-6
    fd_energy = (m.energy(*split(x + h * d)) - m.energy(*split(x - h * d))) / (2 * h)
    assert fd_energy == pytest.approx(R(x) @ d, rel=1e-7)
    K = m.tangent(*split(x))
    fd = (R(x + h * d) - R(x - h * d)) / (2 * h)
    assert np.linalg.norm(fd - K @ d) <= 1e-7 * np.linalg.norm(K @ d)
    assert abs(K - K.T).max() <= 1e-12 * abs(K).max()
    # The reduced force solves the in-plane equilibrium exactly.
    z = x[:n]
    u, v = m.inplane(z)
    _, ru, rv = m.residual(z, u, v)
    assert np.max(np.abs(np.concatenate([ru, rv]))) <= 1e-12 * np.max(np.abs(m.force(z)))


def test_static_small_load_limit_is_the_linear_model(problem, fvk):
    """Difference from the linear model falls as the load squared, <= 1e-5 at 1e-3 of L1."""
    f = _l1(problem, fvk)
    rel = []
    for scale in (1e-1, 1e-2, 1e-3):
        z = fvk.static(fvk.gram @ (scale * f)).z
        zl = fvk.linear.static_deflection(scale * f)
        rel.append(fvk.linear.l2_norm(z - zl) / fvk.linear.l2_norm(zl))
    assert rel[2] <= 1e-5
    orders = np.log10(np.array(rel[:-1]) / np.array(rel[1:]))
    assert np.all(np.abs(orders - 2.0) < 0.02), orders


def test_dynamic_small_load_limit_is_the_linear_model(problem, fvk):
    """Bubble start and L1, both scaled: FvK response vs the linear model's exact ZOH."""
    f = _l1(problem, fvk)
    z0 = fvk.linear.project(bubble(problem.width, problem.height))
    rel = []
    for scale in (1e-2, 1e-3):
        res = integrate(fvk, scale * f, 0.15, z0=scale * z0, substeps=1)
        ref = exact_hold(fvk.linear, scale * f, 0.15, scale * z0)
        rel.append(np.max(np.abs(res.z - ref)) / np.max(np.abs(ref)))
    assert rel[1] <= 1e-5
    assert np.log10(rel[0] / rel[1]) == pytest.approx(2.0, abs=0.05)


def test_generalised_alpha_small_load_limit(problem):
    """The coupled-tangent integrator: FvK vs the linear model integrated by the same scheme."""
    m = FvKMembrane(problem, (13, 7))
    f = _l1(problem, m)
    z0 = m.linear.project(bubble(problem.width, problem.height))
    lin = LinearStructure(m.mass, m.damping, m.linear.stiffness)
    rel = []
    for scale in (1e-2, 1e-3):
        a = alpha_integrate(m, lambda t, s=scale: m.gram @ (s * f), 0.1, s_z0 := scale * z0)
        b = alpha_integrate(lin, lambda t, s=scale: m.gram @ (s * f), 0.1, s_z0)
        rel.append(np.max(np.abs(a.z - b.z)) / np.max(np.abs(b.z)))
    assert rel[1] <= 1e-5
    assert np.log10(rel[0] / rel[1]) == pytest.approx(2.0, abs=0.05)


def test_long_rectangle_tends_to_the_exact_cylindrical_membrane(problem):
    """No prestrain, uniform q on a b x 6b rectangle: at the centre the plane-strain strip solution.

    Strip (derived in docs/membrane_nonlinear.md): ``N^3 = C q^2 b^2 / 24``, ``w0 = q b^2 / (8 N)``,
    ``N_x = nu N`` along the strip.
    """
    b, q = 0.05, 200.0
    mat = problem.material
    C = mat.youngs_modulus * mat.thickness / (1 - mat.poisson_ratio**2)
    N = (C * q * q * b * b / 24) ** (1 / 3)
    w0 = q * b * b / (8 * N)
    # the published design formula (Roark; Bell Helicopter SDM 1977) is the same closed form
    E, t, nu = mat.youngs_modulus, mat.thickness, mat.poisson_ratio
    assert w0 == pytest.approx(b / 8 * (24 * (1 - nu**2) * q * b / (E * t)) ** (1 / 3), rel=1e-12)
    strip = dataclasses.replace(problem, width=6 * b, height=b, sensors=())
    m = FvKMembrane(strip, (73, 13), MembraneParameters(0.0, 0.0))
    s = m.static(load_vector(m.space, lambda x, y: np.full_like(x, q)))
    xc, yc = np.array([3 * b]), np.array([b / 2])
    wc = m.space.evaluate(s.z, xc, yc)[0]
    nx, ny, nxy = m.stress_resultants(s.z, s.u, s.v, xc, yc)
    assert wc / w0 == pytest.approx(1.0, abs=5e-4)  # measured -2.0e-4 (end effects, decay with aspect)
    assert ny[0] / N == pytest.approx(1.0, abs=2e-4)
    assert nx[0] / (mat.poisson_ratio * N) == pytest.approx(1.0, abs=0.02)
    assert abs(nxy[0]) <= 1e-6 * N


def test_static_mesh_convergence_fourth_order(problem):
    """Centre deflection under L1 on 13x7, 25x13, 49x25: observed order about 4 (cubic splines)."""
    L = load_case("L1", problem.width, problem.height)
    wc = []
    for nodes in ((13, 7), (25, 13), (49, 25)):
        m = FvKMembrane(problem, nodes)
        z = m.static(load_vector(m.space, L)).z
        wc.append(m.space.evaluate(z, np.array([problem.width / 2]), np.array([problem.height / 2]))[0])
    order = np.log2(abs(wc[0] - wc[1]) / abs(wc[1] - wc[2]))
    assert 3.7 < order < 4.4, order
    assert abs(wc[1] - wc[2]) <= 1e-5 * wc[2]
    # and the nonlinear membrane is stiffer than the linear one: L1 lowers the centre deflection 12 %
    zl = MembraneModel.from_problem(problem).static_deflection(_l1(problem, m := FvKMembrane(problem)))
    wl = m.space.evaluate(zl, np.array([problem.width / 2]), np.array([problem.height / 2]))[0]
    assert wc[2] / wl == pytest.approx(0.878, abs=0.003)


def test_exponential_and_generalised_alpha_integrators_agree(problem):
    """Two independent integrations of the FvK dynamics converge to each other (13x7, 0.1 s)."""
    m = FvKMembrane(problem, (13, 7))
    f = _l1(problem, m)
    z0 = m.linear.project(bubble(problem.width, problem.height))
    etd = integrate(m, f, 0.1, z0=z0, substeps=4)
    alpha = alpha_integrate(m, lambda t: m.gram @ f, 0.1, z0, settings=AlphaSettings(substeps=16, tol=1e-9))
    s_etd, s_alpha = m.linear.sensors.outputs(etd.z), m.linear.sensors.outputs(alpha.z)
    assert np.max(np.abs(s_etd - s_alpha)) <= 5e-3 * np.max(np.abs(s_alpha))


def test_record_generator(problem):
    rec = simulate_case(problem, "L1", 0.01, 3, (13, 7), 0.2)
    ref = exact_hold(rec.truth_model, rec.truth_model.project(load_case("L1", problem.width, problem.height)), 0.2,
                     rec.truth_model.project(bubble(problem.width, problem.height)))  # fmt: skip
    assert np.max(np.abs(rec.trajectory.z - ref)) <= 1e-10 * np.max(np.abs(ref))
    assert np.allclose(rec.noise_std, 0.01 * np.max(np.abs(rec.trajectory.outputs), axis=0))
    assert rec.true_lift == pytest.approx(200 * problem.width * problem.height * 4 / np.pi**2, rel=1e-9)
    meas = rec.measurements
    assert meas.values.shape == (201, 4) and meas.sensor_names == problem.sensor_names
    g = Gust()
    assert float(g.factor(g.start + g.duration / 2)) == pytest.approx(1.6)
    assert float(g.factor(g.start - 1e-9)) == 1.0 and float(g.factor(g.start + g.duration + 1e-9)) == 1.0
    le = simulate_case(problem, "LE", 0.0, None, (13, 7), 0.05, truth="berger")
    W, L = problem.width, problem.height
    assert le.true_lift == pytest.approx(200 * 256 / 27 / 20 * 2 / np.pi * W * L, rel=1e-9)
    gusty = simulate_case(problem, "L1", 0.0, None, (13, 7), 0.5, gust=g)
    assert gusty.lift_history.max() == pytest.approx(1.6 * rec.true_lift, rel=1e-3)
    dropped = simulate_truth(forward_model(problem, "linear", nodes=(13, 7)), "L1", RecordProtocol(t_end=0.2, drop=0.1))
    lost = np.isnan(dropped.measurements.values).any(axis=1)
    assert 5 <= lost.sum() <= 40 and not lost[0]
    with pytest.raises(InputError, match="truth = 'exact': expected one of linear, berger, fvk"):
        simulate_case(problem, "L1", 0.0, truth="exact")
    with pytest.raises(InputError, match="load"):
        simulate_case(problem, "L9", 0.0)
    with pytest.raises(InputError, match=r"truth-prestrain = \(-0.01, 0.05\): expected two prestrains"):
        simulate_case(problem, "L1", 0.0, prestrain=(-0.01, 0.05))


def test_a_steady_start_is_at_rest_in_the_static_equilibrium(problem):
    """``start="static"``: the record starts loaded and stays there (FvK, no transient)."""
    rec = simulate_case(problem, "L1", 0.0, None, (13, 7), 0.1, truth="fvk", start="static")
    out = rec.trajectory.outputs
    assert np.max(np.abs(out - out[0])) <= 1e-6 * np.max(np.abs(out))


@pytest.mark.slow
def test_fvk_truth_record_time_convergence(problem):
    """49x25 FvK truth, 0.3 s: substeps 2 vs 4 differ by < 1 % of the sensor peak (2nd order)."""
    a = simulate_case(problem, "L1", 0.0, None, t_end=0.3, truth="fvk", substeps=2).trajectory.outputs
    b = simulate_case(problem, "L1", 0.0, None, t_end=0.3, truth="fvk", substeps=4).trajectory.outputs
    peak = np.max(np.abs(b))
    assert np.max(np.abs(a - b)) <= 0.01 * peak


def test_cubic_modal_model_is_exact_on_its_modes_and_close_to_fvk(problem):
    """The projected cubic force equals FvK's; 20 cubic modes track the FvK record to 0.2 %."""
    small = FvKModal.build(MembraneModel.from_problem(problem, (13, 7)), 40, cubic_modes=10)
    fvk_small = FvKMembrane.from_model(small.model)
    a = np.zeros(small.m)
    a[:10] = np.random.default_rng(7).standard_normal(10) * 2e-3
    z = small.deflection(a)
    exact = small.shapes.T @ (fvk_small.force(z) - fvk_small.linear_stiffness @ z)
    assert np.max(np.abs(small.cubic_force(a)[:10] - exact[:10])) <= 1e-12 * np.max(np.abs(exact))
    fvk = FvKMembrane(problem)
    rom = FvKModal.build(fvk.linear, fvk.n, substeps=2, cubic_modes=20)
    f = _l1(problem, fvk)
    z0 = fvk.linear.project(bubble(problem.width, problem.height))
    ref = fvk.linear.sensors.outputs(integrate(fvk, f, 0.3, z0=z0, substeps=2).z)
    out = fvk.linear.sensors.outputs(rom.record(f, 0.3, z0=z0))
    peak = np.max(np.abs(ref), axis=0)
    assert np.sqrt(np.mean(((out - ref) / peak) ** 2)) <= 2e-3  # measured 7e-4 over 1 s
    assert np.max(np.abs(out[-1] / ref[-1] - 1)) <= 3e-3


def test_every_forward_model_has_the_linear_small_load_limit_and_a_static_start(problem):
    """The forward-model protocol: full and modal, linear/Berger/FvK agree at 1e-3 of L1, and each
    model's equilibrium is at rest under its own dynamics."""
    model = MembraneModel.from_problem(problem, (13, 7))
    f = 1e-3 * model.project(load_case("L1", problem.width, problem.height))
    z0 = 1e-3 * model.project(bubble(problem.width, problem.height))
    ref = forward_model(model, "linear").run(f, 0.05, z0=z0).outputs
    for physics in ("linear", "berger", "fvk"):
        for reduced in (False, True):
            fwd = forward_model(model, physics, reduced=reduced, modes=model.n, cubic_modes=8, substeps=2)
            out = fwd.run(f, 0.05, z0=z0).outputs
            assert np.max(np.abs(out - ref)) <= 2e-5 * np.max(np.abs(ref)), (physics, reduced)
            big = 1e3 * f
            zs = fwd.equilibrium(big)
            rest = fwd.run(big, 0.02, z0=zs).outputs
            assert np.max(np.abs(rest - rest[0])) <= 1e-5 * np.max(np.abs(rest[0])), (physics, reduced)
