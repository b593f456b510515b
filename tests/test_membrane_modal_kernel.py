"""The modal membranes' one step loop (``membrane.modal.kernels``) and its two force laws.

Berger and FvK differ only by their force law (``membrane.modal.laws``); the integrator, the record
tangent and the streaming one-sample map are one compiled loop. Checked here: each law is its
model's internal force; the linear law is the exact zero-order hold (an augmented matrix
exponential per mode, independent of the loop); the one-sample map is the record integrator for
both laws (a gain on Berger's stretch included); the forward layer's modal builder builds once.
"""

import numpy as np
import pytest
import scipy.linalg as sla

from wingopt.errors import InputError
from wingopt.membrane import MembraneModel, bubble, load_case
from wingopt.membrane.forward import ModalSample, modal_model
from wingopt.membrane.modal import BergerModal, FvKModal
from wingopt.membrane.modal.laws import stiffness
from wingopt.problem import load_problem

EX, EY, DAMP = 0.045, 0.055, 1.3


@pytest.fixture(scope="module")
def setup():
    model = MembraneModel.from_problem(load_problem("membrane"))
    pr = model.problem
    models = {
        "berger": BergerModal.build(model, 16, substeps=2, stretch_gain=1.45),
        "fvk": FvKModal.build(model, 16, substeps=2, cubic_modes=6),
    }
    z0 = model.project(bubble(pr.width, pr.height, 0.01))
    f = model.project(load_case("L2", pr.width, pr.height))
    return model, models, z0, f


@pytest.mark.parametrize("physics", ["berger", "fvk"])
def test_the_force_law_is_the_models_internal_force(setup, physics):
    """``kk * q + R`` of the compiled law = the model's ``internal_force`` (its own NumPy formula)."""
    _, models, z0, _ = setup
    bm = models[physics]
    q = 3.0 * bm.to_modal(z0)
    _, k0, _, _, _, _ = bm.linear_terms(EX, EY, DAMP)
    rs = bm.force_law()[3].shape[0]
    kk, R = np.empty(bm.m), np.empty(bm.m)
    stiffness(bm.force_law(), q, k0, np.empty((rs, rs)), kk, R)
    F, _ = bm.internal_force(q, EX, EY)
    assert np.abs(kk * q + R - F).max() < 1e-12 * np.abs(F).max()
    assert np.abs(kk * q - k0 * q).max() > 1e-3 * np.abs(F).max()  # the stiffening is there


def test_the_linear_law_is_the_exact_hold(setup):
    """Without the deflection's stiffening both models are ``m`` damped oscillators stepped exactly:
    the same numbers, and those of the matrix exponential of each mode's augmented system."""
    _, models, z0, f = setup
    fm, bm = models["fvk"], models["berger"]
    N = 40
    u = fm.modal_force(f)
    F = np.outer(1.0 + 0.5 * np.sin(np.arange(N) / 5.0), u)
    q0 = fm.to_modal(z0)
    Q = fm.simulate(q0, np.zeros(fm.m), F, EX, EY, DAMP, nonlinear=False)
    assert np.array_equal(Q, bm.simulate(q0, np.zeros(bm.m), F, EX, EY, DAMP, nonlinear=False))
    _, k, _, a, _, _ = fm.linear_terms(EX, EY, DAMP)
    ref = np.empty_like(Q)
    ref[0] = q0
    for j in range(fm.m):
        A = np.array([[0.0, 1.0, 0.0], [-k[j], -2.0 * a[j], 1.0], [0.0, 0.0, 0.0]])
        E = sla.expm(A * fm.dt)
        x = np.array([q0[j], 0.0, 0.0])
        for n in range(N):
            x[2] = F[n, j]
            x = E @ x
            ref[n + 1, j] = x[0]
    assert np.abs(Q - ref).max() < 1e-10 * np.abs(ref).max()


@pytest.mark.parametrize("physics", ["berger", "fvk"])
def test_one_sample_is_the_record_integrator_and_its_tangent(setup, physics):
    """The streaming map is ``simulate`` over one sample (Berger's stretch gain included), and its
    displacement tangent the record tangent's, for the one loop and either law."""
    _, models, z0, f = setup
    bm = models[physics]
    m = bm.m
    rng = np.random.default_rng(5)
    forces = 1e-3 * rng.standard_normal((3, m))
    s = ModalSample(bm, forces, slice(2 * m, 2 * m + 3), slice(2 * m + 3, 2 * m + 6))
    q, v = bm.to_modal(z0), 1e-2 * rng.standard_normal(m)
    u = bm.modal_force(f)
    q1, v1 = s.step(q, v, u, EX, EY, DAMP)
    Q = bm.simulate(q, v, u[None], EX, EY, DAMP)
    assert np.abs(q1 - Q[1]).max() <= 1e-13 * np.abs(Q[1]).max()
    n = 2 * m + 6
    dQ, dV = np.zeros((n, m)), np.zeros((n, m))
    dQ[np.arange(m), np.arange(m)] = 1.0
    dV[m + np.arange(m), np.arange(m)] = 1.0
    a, b, dQ1, _ = s.step_tangent(q, v, u, EX, EY, DAMP, dQ, dV, np.eye(3))
    assert np.array_equal(a, q1) and np.array_equal(b, v1)
    dp = np.zeros((3, n))
    dp[:, -3:] = np.eye(3)
    du = np.zeros((n, m))
    du[2 * m : 2 * m + 3] = forces
    _, dref = bm.simulate_tangent(q, v, u[None], EX, EY, DAMP, dQ, dV, dp, lambda k: du)
    assert np.abs(dQ1 - dref[1]).max() <= 1e-13 * np.abs(dQ1).max()
    # the load rows against a complex step of the same map
    h = 1e-30
    Qc = bm.simulate(q + 0j, v, (u + 1j * h * forces[1])[None], EX, EY, DAMP)
    assert np.abs(Qc[1].imag / h - dQ1[2 * m + 1]).max() < 1e-11 * np.abs(dQ1[2 * m + 1]).max()


def test_the_modal_builder_builds_once_per_wing(setup):
    """``forward.modal_model`` shares the modes and the tensor between sample periods and sub-steps;
    each caller gets its own ``dt``, ``substeps`` and model."""
    model, _, _, _ = setup
    a = modal_model(model, "fvk", 12, 1e-3, 1, cubic_modes=5)
    other = MembraneModel.from_problem(model.problem)
    b = modal_model(other, "fvk", 12, 2e-3, 3, cubic_modes=5)
    assert b.tensor is a.tensor and b.shapes is a.shapes
    assert (b.dt, b.substeps, b.model) == (2e-3, 3, other) and (a.dt, a.substeps, a.model) == (1e-3, 1, model)
    ref = FvKModal.build(model, 12, cubic_modes=5)
    assert np.array_equal(ref.tensor, a.tensor) and np.array_equal(ref.shapes, a.shapes)
    g = modal_model(model, "berger", 12, stretch_gain=1.2)
    assert isinstance(g, BergerModal) and g.stretch_gain == 1.2 and g.dt == model.problem.identification.dt
    with pytest.raises(InputError, match="physics = 'linear'"):
        modal_model(model, "linear", 12)
    with pytest.raises(InputError, match="substeps = 0"):
        modal_model(model, "fvk", 12, 1e-3, 0)
