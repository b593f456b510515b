"""Moving-horizon estimator: model structure, solvers, arrival cost, sign, lambda, accuracy.

Correctness checks run on coarse meshes (13x7 estimator, 25x13 truth, short records); the headline
accuracy check runs the real protocol (25x13 estimator, 49x25 truth, 1 s) on one case.
"""

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

from wingopt.errors import InputError, SolverError
from wingopt.estimation.core.load_space import build_load_space, edge_mass
from wingopt.estimation.core.noise import estimate_noise_std
from wingopt.estimation.core.regularization import (
    LambdaPoint,
    choose_lambda,
    discrepancy_lambda,
    knee_lambda,
)
from wingopt.estimation.mhe import MHESettings, MovingHorizonEstimator, mhe_identify
from wingopt.estimation.mhe.cold_start import sign_score
from wingopt.estimation.mhe.model import MHEModel
from wingopt.estimation.mhe.solvers import make_solver
from wingopt.fe import VALUE, EdgeCondition, SplineBasis1D, TensorSpace, assemble, assemble_mixed, separable
from wingopt.membrane import MembraneModel, forward_model, load_case
from wingopt.optim.status import SolveStatus
from wingopt.workflows.protocols import simulate_case

SMALL = (13, 7)
SMALL_TRUTH = (25, 13)


@pytest.fixture(scope="module")
def small_problem(membrane_problem):
    return membrane_problem.with_mesh(SMALL)


@pytest.fixture(scope="module")
def small_model(small_problem):
    return MembraneModel.from_problem(small_problem)


@pytest.fixture(scope="module")
def small_case(small_problem):
    """L1, 1 % noise, truth on 25x13, 0.3 s."""
    return simulate_case(small_problem, "L1", 0.01, 0, SMALL_TRUTH, t_end=0.3)


@pytest.fixture(scope="module")
def small_estimator(small_model, small_case):
    s = MHESettings(window=100, stride=50, modes=20, regularization=1e-6)
    return MovingHorizonEstimator(small_model, s).setup(small_case.measurements)


# -- load spaces and the mixed assembly ------------------------------------------------------------
def test_mixed_assembly_matches_full_space_restriction(small_model):
    zero = small_model.space
    free = TensorSpace(
        SplineBasis1D(zero.width, zero.bx.n_elements, EdgeCondition.FREE, EdgeCondition.FREE),
        SplineBasis1D(zero.height, zero.by.n_elements, EdgeCondition.FREE, EdgeCondition.FREE),
    )
    mass = separable((1.0, VALUE, VALUE))
    G_kron = assemble_mixed(zero, free, mass, method="kron")
    G_cell = assemble_mixed(zero, free, mass, method="cells")
    G_full = assemble(free, mass)  # the free space is the full spline space: T_free = I
    ref = zero.transform.T @ G_full
    assert G_kron.shape == (zero.n, free.n)
    assert abs(G_kron - ref).max() <= 1e-15 * abs(ref).max() * 10
    assert abs(G_cell - ref).max() <= 1e-13 * abs(ref).max()
    # Same space on both sides is the ordinary assembly.
    assert abs(assemble_mixed(zero, zero, mass) - small_model.gram).max() <= 1e-15
    with pytest.raises(ValueError):
        assemble_mixed(zero, TensorSpace(SplineBasis1D(zero.width, 5), zero.by), mass)


def test_free_load_space_coupling_and_edge_load(small_model, membrane_problem):
    free = build_load_space(small_model, "free")
    fixed = build_load_space(small_model, "fixed")
    assert free.n == (SMALL[0] + 2) * (SMALL[1] + 2)
    # A uniform pressure: coupling @ f = ∫ phi_w (the deflection basis integrals), lift = area.
    one = free.project(lambda x, y: np.ones_like(x))
    assert np.allclose(free.coupling @ one, small_model.basis_integrals, rtol=1e-10, atol=1e-14)
    assert free.lift(one) == pytest.approx(membrane_problem.width * membrane_problem.height, rel=1e-12)
    # L3 is largest on the edge x = W: the fixed space cannot hold it, the free space can.
    L3 = load_case("L3", membrane_problem.width, membrane_problem.height)
    from wingopt.membrane import relative_l2

    e_fixed = relative_l2(small_model.space, L3, fixed.field(fixed.project(L3)))
    e_free = relative_l2(small_model.space, L3, free.field(free.project(L3)))
    assert e_fixed > 0.08 and e_free < 0.01
    # The edge term: ∮ 1 ds is the perimeter.
    assert one @ edge_mass(free.space) @ one == pytest.approx(
        2 * (membrane_problem.width + membrane_problem.height), rel=1e-12
    )


# -- reduced model --------------------------------------------------------------------------------
def test_window_prediction_is_the_exact_discrete_model(small_model, small_problem):
    """All modes kept: the window's linear map reproduces the simulator (exact ZOH) to round-off."""
    ls = build_load_space(small_model, "fixed")
    red = MHEModel.build(small_model, ls, modes=None)
    load = load_case("L2", small_problem.width, small_problem.height)
    z0 = small_model.project(lambda x, y: 0.003 * np.sin(np.pi * x / 0.14) * np.sin(np.pi * y / 0.07))
    traj = forward_model(small_model, "linear").run(load, t_end=0.05, z0=z0)
    theta = np.concatenate([red.to_modal(z0), np.zeros(red.m), red.modal_forces(ls.project(load))])
    basis = red.window(traj.t.size)
    Y = red.outputs(red.modal_trajectory(basis, theta))
    assert np.allclose(Y, traj.outputs, rtol=1e-9, atol=1e-12 * traj.outputs.max())


def test_modal_truncation_keeps_steady_outputs(membrane_models, membrane_problem):
    """40 of 325 modes: steady sensor outputs of L3 (the least smooth load) within 0.5 %."""
    model = membrane_models[(25, 13)]
    ls = build_load_space(model, "fixed")
    red = MHEModel.build(model, ls, modes=40)
    f = ls.project(load_case("L3", membrane_problem.width, membrane_problem.height))
    exact = model.sensors.outputs(model.static_deflection(f))
    q = red.modal_forces(f) / red.omega**2
    approx = red.outputs(q[None, :])[0]
    assert np.max(np.abs(approx / exact - 1)) < 5e-3
    # The static correction restores the full static deflection.
    z = red.deflection(q, f)
    assert np.allclose(z, model.static_deflection(f), rtol=1e-8, atol=1e-12)


def test_jacobian_and_exact_hessian_match_finite_differences(small_estimator):
    est = small_estimator
    problem = est._window_problem(0, est.lam)
    rng = np.random.default_rng(1)
    D = problem.scale
    theta = est._sol.theta * (1 + 0.1 * rng.standard_normal(problem.dim))
    d = D * rng.standard_normal(problem.dim) * 1e-4
    r0, J = problem.linearize(theta)
    r1, _ = problem.linearize(theta + d)
    r2, _ = problem.linearize(theta - d)
    assert np.allclose((r2 - r1) / 2, J @ d, rtol=1e-6, atol=1e-9 * np.abs(J @ d).max())
    # Gradient of the half cost is -b; its derivative along d is (H_GN + second order) d.
    H, b = problem.normal_equations(theta)
    _, bp = problem.normal_equations(theta + d)
    _, bm = problem.normal_equations(theta - d)
    Hx = H + problem.second_order(theta)
    fd = -(bp - bm) / 2  # b is cubic in theta: the central difference is off by O(|d|^2)
    assert np.linalg.norm(fd - Hx @ d) <= 1e-4 * np.linalg.norm(fd)
    assert np.linalg.norm(fd - H @ d) >= 1e-2 * np.linalg.norm(fd)  # Gauss–Newton alone is not exact


# -- solvers --------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "backend,kw",
    [
        ("numpy", {}),
        ("cvxpy", {"qp_solver": "clarabel"}),
        ("cvxpy", {"qp_solver": "osqp"}),
        ("ipopt", {}),
        ("ipopt", {"hessian": "ad"}),
    ],
)
def test_backends_agree_on_one_window(small_estimator, backend, kw):
    est = small_estimator
    problem = est._window_problem(0, est.lam)
    ref = est._sol.theta
    start = ref * (1 + 0.05 * np.random.default_rng(0).standard_normal(ref.size))
    sol = make_solver(backend, **kw).solve(problem, start)
    assert sol.status in (SolveStatus.OPTIMAL, SolveStatus.OPTIMAL_INACCURATE)
    D = problem.scale
    assert np.linalg.norm((sol.theta - ref) / D) <= 2e-3 * np.linalg.norm(ref / D)
    m = est.reduced.m
    lift = est.reduced.lift_row @ sol.theta[2 * m :]
    assert lift == pytest.approx(est.reduced.lift_row @ ref[2 * m :], rel=1e-5)
    assert sol.cost == pytest.approx(problem.cost(ref), rel=1e-6)


def test_pressure_bounds_cvxpy_and_ipopt_agree(small_model, small_case):
    """A binding upper bound (150 Pa on a 200 Pa load): both backends respect it and agree."""
    res = {}
    for backend in ("cvxpy", "ipopt"):
        s = MHESettings(window=100, stride=100, modes=20, regularization=1e-6, backend=backend)
        s = s.replace(pressure_bounds=(-10.0, 150.0), bound_grid=(9, 5))
        est = MovingHorizonEstimator(small_model, s).setup(small_case.measurements)
        P = est.bounds_points @ est._sol.theta[-est.reduced.m :]
        assert P.max() <= 150.0 + 1e-3 and P.min() >= -10.0 - 1e-3
        assert P.max() >= 149.0  # binding
        res[backend] = est.current_lift
    assert res["cvxpy"] == pytest.approx(res["ipopt"], rel=2e-3)


def test_infeasible_bounds_raise_solver_error_naming_the_backend(small_model, small_case):
    # The fixed-edge load is zero on the edges: a lower bound of 50 Pa everywhere cannot hold.
    s = MHESettings(window=100, stride=100, modes=20, regularization=1e-6, backend="cvxpy")
    s = s.replace(pressure_bounds=(50.0, 300.0), bound_grid=(5, 3))
    with pytest.raises(SolverError) as exc:
        MovingHorizonEstimator(small_model, s).setup(small_case.measurements)
    assert exc.value.backend.startswith("cvxpy") and "infeasible" in exc.value.status.lower()


def test_settings_validation():
    with pytest.raises(InputError, match="stride"):
        MHESettings(window=100, stride=200)
    with pytest.raises(InputError, match="divisor"):
        MHESettings(window=100, stride=30, load_model="random_walk")
    with pytest.raises(InputError, match="backend"):
        MHESettings(pressure_bounds=(0.0, 100.0))
    with pytest.raises(InputError, match="load_space"):
        MHESettings(load_space="edgy")
    with pytest.raises(InputError, match="stride_s"):
        MHESettings(window_s=0.1, stride_s=0.2)
    with pytest.raises(InputError, match="load_timescale"):
        MHESettings(load_timescale=0.0)


def test_window_in_seconds_follows_the_sample_rate():
    """Default 0.2 s / 0.05 s: 200/50 samples at 1 kHz, 60/15 at 300 Hz; samples given win; the
    random walk rounds the window to whole strides."""
    s = MHESettings()
    assert s.samples(1e-3) == (200, 50)
    assert s.samples(1 / 300) == (60, 15)
    assert MHESettings(window=100, stride=25).samples(1 / 300) == (100, 25)
    assert MHESettings(load_model="random_walk", window_s=0.21).samples(1e-3) == (200, 50)
    with pytest.raises(InputError, match="divisor"):
        MHESettings(load_model="random_walk", window=100, stride_s=0.03).samples(1e-3)


# -- arrival cost, sign, random walk -------------------------------------------------------------
def test_moving_windows_reproduce_the_batch_estimate(small_model, small_case):
    """Constant load, exact arrival cost: sliding windows end where one batch window over the record does."""
    s = MHESettings(window=100, stride=50, modes=20, regularization=1e-6)
    mhe = mhe_identify(small_model, small_case.measurements, s)
    batch = mhe_identify(small_model, small_case.measurements, s.replace(window=301, stride=301))
    assert mhe.info["windows"] == 6 and batch.info["windows"] == 1  # the last step is 1 sample
    assert mhe.lift[-1] == pytest.approx(batch.lift[-1], rel=2e-3)
    diff = small_model.l2_norm(mhe.final_load - batch.final_load) / small_model.l2_norm(batch.final_load)
    assert diff < 5e-3


def test_sign_follows_the_prior(small_model, small_case):
    s = MHESettings(window=100, stride=100, modes=20, regularization=1e-6)
    pos = MovingHorizonEstimator(small_model, s).setup(small_case.measurements)
    assert pos.current_lift > 0 and pos.start_report.sign_score > 1.5
    # Negative prior load and bubble: the mirror image, same data misfit.
    neg = MovingHorizonEstimator(small_model, s).setup(
        small_case.measurements, initial_load=-200.0, initial_deflection=-0.01
    )
    assert neg.current_lift == pytest.approx(-pos.current_lift, rel=1e-3)
    assert neg._sol.cost == pytest.approx(pos._sol.cost, rel=1e-6)
    assert sign_score(neg.reduced, neg._sol.theta, neg.sign_prior) > 1.5


def test_the_sign_prior_is_the_declaration_the_settings_carry(small_model, small_case):
    s = MHESettings(window=100, stride=100, modes=20, regularization=1e-6)
    pos = MovingHorizonEstimator(small_model, s).setup(small_case.measurements)
    assert pos.settings.declaration == small_model.problem.identification  # filled from the problem
    # A declaration given by the caller is the one read: its prior load and bubble flip the sign.
    own = dataclasses.replace(small_model.problem.identification, initial_load=-200.0, initial_deflection=-0.01)
    neg = MovingHorizonEstimator(small_model, s.replace(declaration=own)).setup(small_case.measurements)
    assert (neg.initial_load, neg.initial_deflection) == (-200.0, -0.01)
    assert neg.current_lift == pytest.approx(-pos.current_lift, rel=1e-3)


def test_start_from_rest_without_deflection_prior(small_model, small_problem):
    """Plant at rest, no bubble: the scan starts off zero (where 2 x^T C_i vanishes) and converges;
    the sign of L1 comes from initial_load alone; L2 (no net lift) is flagged as undetermined."""
    from wingopt.measurements.series import Measurements
    from wingopt.membrane import add_noise

    truth = MembraneModel.from_problem(small_problem, SMALL_TRUTH)
    out = {}
    for name in ("L1", "L2"):
        load = load_case(name, small_problem.width, small_problem.height)
        traj = forward_model(truth, "linear").run(load, t_end=0.3)
        y, _ = add_noise(traj.outputs, 0.01, 0)
        meas = Measurements(traj.t, y, small_problem.sensor_names)
        s = MHESettings(window=100, stride=50, modes=20)
        res = mhe_identify(small_model, meas, s, initial_deflection=0.0)
        from wingopt.membrane import relative_l2
        from wingopt.workflows.studies import load_field

        out[name] = (relative_l2(truth.space, load, load_field(res, small_model)), res.info["sign"])
    err, sign = out["L1"]
    assert err < 0.03 and sign["determined"]  # measured 0.015
    err, sign = out["L2"]
    assert not sign["determined"]
    assert min(err, 2 - err) < 0.05  # the shape is right up to the undetermined sign (measured 0.027)


def test_random_walk_tracks_a_load_step(small_model, small_problem):
    """The load doubles at 0.25 s. The random walk follows it; so does the constant model, whose
    consistency test sees the data contradict the estimate and restarts it after the step (without
    the test it averages the two levels)."""
    f1 = small_model.project(load_case("L1", small_problem.width, small_problem.height))
    from wingopt.measurements.series import Measurements
    from wingopt.membrane import add_noise, bubble

    dt = small_problem.identification.dt
    traj = forward_model(small_model, "linear").run(
        lambda t: f1 * (1.0 if t < 0.25 else 2.0), t_end=0.5, z0=bubble(0.14, 0.07)
    )
    y, sigma = add_noise(traj.outputs, 0.01, 3)
    meas = Measurements(traj.t, y, small_problem.sensor_names, sigma)
    s = MHESettings(window=100, stride=25, modes=20, regularization=1e-6, load_model="random_walk")
    res = mhe_identify(small_model, meas, s)
    lift_true = small_model.lift(f1)
    assert res.lift[np.searchsorted(res.t, 0.2)] == pytest.approx(lift_true, rel=0.05)
    assert res.lift[-1] == pytest.approx(2 * lift_true, rel=0.05)
    const = mhe_identify(small_model, meas, s.replace(load_model="constant", stride=50))
    assert const.lift[-1] == pytest.approx(2 * lift_true, rel=0.05)
    # The first window that contains the step fits neither level (restart at its first misfit
    # segment, 0.2 s); the next one starts at the step and is consistent.
    starts = [r["t_start"] for r in const.info["restarts"]]
    assert 1 <= len(starts) <= 3 and starts[-1] == pytest.approx(0.25, abs=0.02)
    blind = mhe_identify(small_model, meas, s.replace(load_model="constant", stride=50, consistency=False))
    assert abs(blind.lift[-1] - 2 * lift_true) > 0.1 * lift_true
    assert dt == pytest.approx(res.t[1] - res.t[0])


def test_consistency_profile_finds_a_leading_misfit():
    """Chi-square segments: a leading run of misfit is the onset; the level is the median of the
    consistent ones (floored at 1); leverage lowers a segment's degrees of freedom."""
    from wingopt.estimation.mhe.consistency import first_inconsistent, leading_onset, segment_profile

    rng = np.random.default_rng(0)
    r2 = rng.standard_normal((200, 4)) ** 2
    counted = np.ones_like(r2, dtype=bool)
    prof = segment_profile(r2, counted, 10)
    assert leading_onset(prof) == 0 and first_inconsistent(prof) is None
    assert prof.level == pytest.approx(1.0, abs=0.15)
    bad = r2.copy()
    bad[:25] *= 30.0  # the onset: 25 samples the model cannot explain
    prof = segment_profile(bad, counted, 10)
    assert leading_onset(prof) == 30 and first_inconsistent(prof) == 0
    late = r2.copy()
    late[150:160] *= 30.0
    prof = segment_profile(late, counted, 10)
    assert leading_onset(prof) == 0 and first_inconsistent(prof) == 150
    # An overestimated noise level (misfit 0.25 per datum) does not make the test over-sensitive.
    assert segment_profile(0.25 * r2, counted, 10).level == 1.0
    # Missing data count for nothing; a fit that absorbs the noise (leverage) has fewer dof.
    holes = counted.copy()
    holes[:10] = False
    assert segment_profile(np.where(holes, r2, 0.0), holes, 10).n[0] == 0
    lev = np.zeros(200)
    lev[:10] = 3.0
    assert segment_profile(r2, counted, 10, leverage=lev).threshold[0] < prof.threshold[0]


def test_random_walk_process_noise_is_the_inverse_covariance(small_model):
    """Woodbury form of the random walk's increment information: (tau/T_a) v v^T + (tau/T_s) G^-1
    (relative to the reference load) inverted; the amplitude direction is cheap, shape changes are not."""
    from wingopt.estimation.mhe.load_model import RandomWalk, l2_metric

    ls = build_load_space(small_model, "fixed")
    red = MHEModel.build(small_model, ls, 20)
    u = red.modal_forces(small_model.project(load_case("L1", 0.14, 0.07)))
    rw = RandomWalk.build(red, 1.0, 100.0, u)
    G = l2_metric(red)
    size2 = u @ G @ u
    tau = 0.05
    Q = size2 * (tau / 1.0 * np.outer(u, u) / size2 + tau / 100.0 * np.linalg.inv(G))
    P = rw.precision(tau)
    assert np.allclose(P @ Q, np.eye(red.m), atol=1e-6)
    assert u @ P @ u == pytest.approx(1.0 / (tau + tau / 100.0), rel=1e-9)  # 1-sigma: |f| sqrt(tau / T)


def test_missing_samples_are_skipped(small_model, small_case):
    meas = small_case.measurements
    vals = meas.values.copy()
    vals[100:140] = np.nan
    vals[200, 2] = np.nan
    holey = dataclasses.replace(meas, values=vals)
    s = MHESettings(window=100, stride=50, modes=20, regularization=1e-6)
    res = mhe_identify(small_model, holey, s)
    ref = mhe_identify(small_model, meas, s)
    assert res.info["missing_samples"] == 41
    assert res.lift[-1] == pytest.approx(ref.lift[-1], rel=5e-3)


# -- lambda and noise ---------------------------------------------------------------------------
def _path(chi2, dof=50.0, n=800):
    lams = 10.0 ** np.arange(len(chi2))
    return [LambdaPoint(float(l), float(c), dof, n) for l, c in zip(lams, chi2)]


def test_lambda_rules_on_a_synthetic_path():
    # Floor 760, knee threshold 760 + 0.5 sqrt(1600) = 780 between 1e3 (770) and 1e4 (790).
    path = _path([760.0, 761.0, 765.0, 770.0, 790.0, 4000.0, 40000.0])
    lam_k = knee_lambda(path)
    assert 1e3 < lam_k < 1e4
    lam, info = choose_lambda(path, "robust")
    assert lam == pytest.approx(lam_k / 3)
    # Plain discrepancy (chi2 <= n - dof = 750) finds nothing: model error keeps chi2 above it.
    assert discrepancy_lambda(path, 1.0) is None
    lam_d, info_d = choose_lambda(path, "discrepancy")
    assert lam_d == 1.0 and "fallback" in info_d
    lam_g, _ = choose_lambda(path, "gcv")
    assert lam_g < lam_k


def test_noise_estimate_from_second_differences():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 1, 1001)
    clean = np.column_stack([0.01 + 0.002 * np.exp(-5 * t), 0.02 * np.ones_like(t)])
    sigma = np.array([1e-4, 3e-4])
    y = clean + rng.standard_normal(clean.shape) * sigma
    y[500, 0] = np.nan
    est = estimate_noise_std(y)
    assert np.allclose(est, sigma, rtol=0.08)


# -- headline accuracy (25x13 estimator, 49x25 truth, 1 s) ---------------------------------------
def test_l1_protocol_accuracy_and_lambda_from_data(membrane_problem, membrane_models):
    case = simulate_case(membrane_problem, "L1", 0.01, 0)
    model = membrane_models[(25, 13)]
    meas = dataclasses.replace(case.measurements, noise_std=None)  # noise level estimated too
    res = mhe_identify(model, meas)
    from wingopt.workflows.studies import load_field

    err = case.load_error(load_field(res, model))
    assert err < 0.02  # measured 0.014
    assert case.deflection_error(model.field(res.final_deflection)) < 0.01  # measured 0.006
    assert abs(res.lift[-1] - case.true_lift) < 0.02 * case.true_absolute_load
    assert res.info["lambda_selection"]["rule"] == "robust"
    assert res.info["noise_source"] == "estimated from the data"
    assert 0 < res.lift_std[-1] < 0.05
    assert np.all(np.diff(res.t) > 0) and res.load.shape == (1001, model.n)
    assert sp.issparse(model.gram)


# -- evidence and the evidence-chosen state prior ------------------------------------------------
def test_log_evidence_matches_a_direct_gaussian_computation(small_estimator):
    """Laplace evidence of a window: prior mean from (H0, g0), c0 ignored, scaled = unscaled."""
    est = small_estimator
    problem = est._window_problem(0, est.lam)
    theta = est._sol.theta
    _, J = problem.linearize(theta)
    mu = np.linalg.solve(problem.H0, problem.g0)
    d = theta - mu
    H = J.T @ J + problem.H0
    direct = -0.5 * (problem.data_cost(theta) + d @ problem.H0 @ d)
    direct -= 0.5 * (np.linalg.slogdet(H)[1] - np.linalg.slogdet(problem.H0)[1])
    assert problem.log_evidence(theta) == pytest.approx(direct, rel=1e-6, abs=1e-4)
    shifted = dataclasses.replace(problem, c0=123.0)
    assert shifted.log_evidence(theta) == pytest.approx(problem.log_evidence(theta), rel=1e-12)
    # The optimum has more evidence than a perturbed point of the same Gaussian approximation.
    assert problem.log_evidence(theta) > problem.log_evidence(theta * (1 + 1e-2))


def test_state_prior_chosen_by_the_evidence(small_model, small_case):
    """The plant starts from the bubble: with the bubble as prior the data prefer a tight state
    prior; with rest as the (wrong) prior they prefer the weak one."""
    s = MHESettings(window=100, stride=50, modes=20, state_prior_choices=(1.0, 1e-3))
    est = MovingHorizonEstimator(small_model, s).setup(small_case.measurements)
    info = est.result().info["state_prior"]
    assert info["rule"] == "evidence" and info["chosen"] == 1e-3
    assert info["log_evidence"][1e-3] > info["log_evidence"][1.0] + 20
    assert est.lambda_info["path"][0]["log_evidence"] is not None
    rest = MovingHorizonEstimator(small_model, s).setup(small_case.measurements, initial_deflection=0.0)
    assert rest.state_prior == 1.0
    with pytest.raises(InputError, match="state_prior_choices"):
        MHESettings(state_prior_choices=(1.0, 0.0))


def test_random_walk_covariance_is_amplitude_plus_slow_shape(small_estimator):
    """``Q(tau) = |f^|^2 [(tau/T_a) v v^T + (tau/T_s) G^-1]`` (mhe_load_model): the precision is its
    inverse, the amplitude direction has relative variance ``tau/T_a + tau/T_s`` and a zero
    reference load is refused with an error naming the load model."""
    from wingopt.errors import InputError
    from wingopt.estimation.mhe.load_model import RandomWalk, l2_metric

    red = small_estimator.reduced
    G = l2_metric(red)
    u = np.linalg.solve(G, np.ones(red.m))  # any reference load
    rw = RandomWalk.build(red, 0.5, 50.0, u)
    tau = 0.05
    size2 = float(u @ G @ u)
    Q = size2 * ((tau / 0.5) * np.outer(u, u) / size2 + (tau / 50.0) * np.linalg.inv(G))
    np.testing.assert_allclose(rw.precision(tau) @ Q, np.eye(red.m), atol=1e-8)
    # Relative variance of the amplitude (the component along u in the metric G).
    amp = (G @ u) / size2
    assert amp @ u == pytest.approx(1.0) and amp @ Q @ amp == pytest.approx(tau / 0.5 + tau / 50.0, rel=1e-10)
    with pytest.raises(InputError, match="random_walk"):
        RandomWalk.build(red, 0.5, 50.0, np.zeros(red.m))
