"""The modal membranes' compiled time loop (``membrane.modal.kernels``, one loop for the Berger and
the cubic FvK force laws): real against complex runs, the tangent against complex-step derivatives,
the whole-record tangent against the sample-by-sample one, the settled-trajectory stop, and the
Levenberg–Marquardt convergence test on the Newton decrement."""

import numpy as np
import pytest
from scipy.optimize import least_squares

from wingopt.estimation.core.record_fit import levenberg_marquardt
from wingopt.membrane import MembraneModel, bubble, load_case
from wingopt.membrane.modal import BergerModal, FvKModal
from wingopt.membrane.modal import kernels as fvk_kernels
from wingopt.membrane.modal.tangent import ForceTangent
from wingopt.problem import load_problem

N = 120
EX, EY, DAMP = 0.045, 0.055, 1.3


@pytest.fixture(scope="module")
def models():
    model = MembraneModel.from_problem(load_problem("membrane"))
    pr = model.problem
    fm = FvKModal.build(model, 20, substeps=2, cubic_modes=8)
    bm = BergerModal.build(model, 20, substeps=2)
    q0 = fm.to_modal(model.project(bubble(pr.width, pr.height)))
    u = fm.input_matrix @ model.project(load_case("L1", pr.width, pr.height))
    return {"fvk": (fm, q0, u), "berger": (bm, q0, u)}


@pytest.fixture(scope="module")
def small(models):
    return models["fvk"]


def _seeds(fm, u, gust: bool):
    rng = np.random.default_rng(3)
    P, m = 7, fm.m
    amp = 1.0 + (0.3 * np.sin(np.arange(N + 1) / 9.0) if gust else np.zeros(N + 1))
    hats = rng.random((N + 1, 2)) if gust else np.zeros((N + 1, 0))
    base = np.abs(u).max() * rng.standard_normal((P, m))
    ft = ForceTangent(amp, base, hats, 4, u)
    dq0, dv0 = 1e-3 * rng.standard_normal((P, m)), 0.3 * rng.standard_normal((P, m))
    dpar = rng.standard_normal((3, P)) * np.array([[0.01], [0.01], [0.5]])
    return amp[:-1, None] * u[None], ft, dq0, dv0, dpar


@pytest.mark.parametrize("physics", ["fvk", "berger"])
@pytest.mark.parametrize("nonlinear", [True, False])
def test_real_and_complex_runs_are_the_same_numbers(models, physics, nonlinear):
    """Real and complex arguments run the same loop (complex arithmetic, cos/sin of a complex root
    where the real one takes cosh/sinh below zero): the same numbers; a batch is each trajectory."""
    fm, q0, u = models[physics]
    F, *_ = _seeds(fm, u, gust=True)
    Q = fm.simulate(q0, np.zeros(fm.m), F, EX, EY, DAMP, nonlinear=nonlinear)
    ref = fm.simulate(q0 + 0j, np.zeros(fm.m), F, EX, EY, DAMP, nonlinear=nonlinear).real
    assert np.abs(Q - ref).max() < 1e-13 * np.abs(ref).max()
    # a batch (the start-up scan) is each trajectory of it
    B = fm.simulate(np.stack([q0, -q0]), np.zeros(fm.m), F[:, None] * np.array([1.0, 2.0])[None, :, None], EX, EY)
    one = fm.simulate(-q0, np.zeros(fm.m), 2.0 * F, EX, EY)
    assert np.array_equal(B[:, 1], one)


@pytest.mark.parametrize("physics", ["fvk", "berger"])
@pytest.mark.parametrize("nonlinear", [True, False])
def test_compiled_tangent_is_the_exact_derivative(models, physics, nonlinear):
    """The whole-record tangent (gust columns included) = the sample-by-sample tangent = complex
    step, to rounding."""
    fm, q0, u = models[physics]
    F, ft, dq0, dv0, dpar = _seeds(fm, u, gust=True)
    args = (q0, np.zeros(fm.m), F, EX, EY, DAMP, dq0, dv0, dpar)
    Q, dQ = fm.simulate_tangent(*args, ft, nonlinear)
    Qn, dQn = fm.simulate_tangent(*args, lambda k: ft(k), nonlinear)  # any callable: one sample at a time
    assert np.abs(Q - Qn).max() < 1e-13 * np.abs(Qn).max()
    assert np.abs(dQ - dQn).max() < 1e-13 * np.abs(dQn).max()
    h = 1e-30
    dF = np.stack([ft(k) for k in range(N)])  # (N, P, m)
    s = 1j * h
    Qc = fm.simulate(
        q0 + s * dq0, s * dv0, F[:, None] + s * dF, EX + s * dpar[0], EY + s * dpar[1], DAMP + s * dpar[2],
        nonlinear=nonlinear,
    )  # fmt: skip
    assert np.abs(Qc.imag / h - dQ).max() < 1e-12 * np.abs(dQ).max()


def test_a_settled_trajectory_stops_within_its_tolerance(small):
    """Under a constant force the loops stop once the state (and tangent) stop changing; the rest of
    the record is the last state, within ~30x the settling tolerance of the full integration (the
    tangent's tolerance is looser: a Jacobian needs fewer digits than the residuals)."""
    fm, q0, u = small
    n = 1500
    F = np.tile(u, (n, 1))
    Q = fm.simulate(q0, np.zeros(fm.m), F, EX, EY, DAMP)
    ref = fm.simulate(q0 + 0j, np.zeros(fm.m), F, EX, EY, DAMP).real
    moved = np.flatnonzero(np.any(Q[1:] != Q[:-1], axis=1))
    assert moved[-1] + 1 < n  # it did stop ...
    assert np.abs(Q - ref).max() < 30 * fvk_kernels.SETTLE_TOL * np.abs(ref).max()  # ... at the answer
    rng = np.random.default_rng(0)
    P = 5
    ft = ForceTangent(np.ones(n + 1), rng.standard_normal((P, fm.m)), np.zeros((n + 1, 0)), 0, u)
    seeds = (1e-3 * rng.standard_normal((P, fm.m)), np.zeros((P, fm.m)), np.zeros((3, P)))
    Qt, dQ = fm.simulate_tangent(q0, np.zeros(fm.m), F, EX, EY, DAMP, *seeds, ft)
    _, dQn = fm.simulate_tangent(q0, np.zeros(fm.m), F, EX, EY, DAMP, *seeds, lambda k: ft(k))
    # the tangent is held once settled to its own (looser) tolerance; the state goes on to its own
    assert np.abs(dQ - dQn).max() < 30 * fvk_kernels.SETTLE_TOL_TANGENT * np.abs(dQn).max()
    assert np.abs(Qt - ref).max() < 30 * fvk_kernels.SETTLE_TOL * np.abs(ref).max()
    assert np.flatnonzero(np.any(dQ[1:] != dQ[:-1], axis=(1, 2)))[-1] < moved[-1]  # the tangent stopped first
    # a force that changes up to the end never settles early
    assert fvk_kernels.settled_from(F) == 0
    assert fvk_kernels.settled_from(np.vstack([F[:-1], 2 * F[-1:]])) == n - 1


class _Exponentials:
    """``y = a exp(-b t) + c`` with a Gaussian prior: a small nonlinear least-squares problem."""

    def __init__(self):
        self.t = np.linspace(0, 4, 60)
        rng = np.random.default_rng(2)
        self.y = 2.0 * np.exp(-1.3 * self.t) + 0.5 + 0.01 * rng.standard_normal(self.t.size)
        self.sigma = 0.01

    def residuals(self, th, jacobian=False):
        a, b, c = th
        e = np.exp(-b * self.t)
        rd = (self.y - a * e - c) / self.sigma
        rp = 0.1 * th
        if not jacobian:
            return rd, rp
        J = -np.stack([e, -a * self.t * e, np.ones_like(e)], axis=1) / self.sigma
        return rd, rp, J, 0.1 * np.eye(3)


def test_lm_converges_on_the_newton_decrement():
    """Converged means the undamped Gauss-Newton step would gain less than ``tol``; the minimum is
    scipy's least_squares' to within ``sqrt(tol)`` posterior standard deviations."""
    prob = _Exponentials()
    fit = levenberg_marquardt(prob, np.array([1.0, 0.5, 0.0]), tol=1e-6)
    rd, rp, J, R = prob.residuals(fit.theta, jacobian=True)
    H, g = J.T @ J + R.T @ R, J.T @ rd + R.T @ rp
    assert fit.converged and g @ np.linalg.solve(H, g) < 1e-6
    ref = least_squares(lambda th: np.concatenate(prob.residuals(th)), [1.0, 0.5, 0.0], xtol=1e-14, ftol=1e-14)
    d = fit.theta - ref.x
    assert d @ H @ d < 1e-5 and np.allclose(fit.theta, ref.x, rtol=1e-5)
    # the iteration cap is honoured and reported as not converged
    capped = levenberg_marquardt(prob, np.array([1.0, 0.5, 0.0]), max_iter=1, tol=1e-12)
    assert capped.iterations == 1 and not capped.converged
