"""Morphing QP: static optimum, parametric QP assembly, backends, steady state (7x31, fast)."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import lsq_linear

from wingopt.control.mpc import QPSettings, TrackingProblem, _shift, assemble_qp, make_qp_controller
from wingopt.control.static_optimum import static_fields, static_optimum
from wingopt.control.tracking import R_DEFAULT, steady_state
from wingopt.errors import InputError, SolverError
from wingopt.optim import BACKENDS, ParametricQP, make_backend
from wingopt.optim.status import SolveStatus
from wingopt.plate import PlateModel
from wingopt.problem import load_problem

VMIN, VMAX = -500.0, 1500.0
SHAPES = ("twist", "camber", "bending")


@pytest.fixture(scope="module")
def plate():
    return PlateModel.from_problem(load_problem("plate"), (7, 31))


@pytest.fixture(scope="module")
def fields(plate):
    return static_fields(plate)


@pytest.fixture(scope="module")
def problems(plate, fields):
    """Tracking problems of the three shapes at the default limits (clarabel for the static optimum)."""
    return {
        s: TrackingProblem.build(plate, plate.target(s), period=0.01, vmin=VMIN, vmax=VMAX, fields=fields)
        for s in SHAPES
    }


# -- static optimum -----------------------------------------------------------------------------------


@pytest.mark.parametrize("shape", SHAPES)
def test_static_optimum_is_the_bounded_least_squares_fit(plate, fields, shape):
    zd = plate.target(shape)
    so = static_optimum(plate, zd, vmin=VMIN, vmax=VMAX, fields=fields, input_weight=0.0)
    assert so.status is SolveStatus.OPTIMAL
    assert np.all(so.voltages >= VMIN) and np.all(so.voltages <= VMAX)
    # Independent check: scipy's bounded-variable least squares on L^T u = L^-1 g (M = L L^T).
    MZ = plate.mass @ fields
    L = np.linalg.cholesky(fields.T @ MZ)
    ref = lsq_linear(L.T, np.linalg.solve(L, MZ.T @ zd), bounds=(VMIN, VMAX), method="bvls", tol=1e-14)
    z_ref = fields @ ref.x
    err_ref = plate.m_norm(z_ref - zd) / plate.m_norm(zd)
    assert so.shape_error == pytest.approx(err_ref, rel=1e-6)
    np.testing.assert_allclose(so.voltages, ref.x, atol=1e-3 * (VMAX - VMIN))
    # The limits matter: the unconstrained fit is far better, and needs kilovolts beyond them.
    free = static_optimum(plate, zd, fields=fields, backend="direct", input_weight=0.0)
    assert free.shape_error < 0.5 * so.shape_error
    assert free.voltages.max() > VMAX or free.voltages.min() < VMIN
    assert so.active.sum() >= 2


def test_static_optimum_agrees_across_backends(plate, fields):
    zd = plate.target("camber")
    objs = {b: static_optimum(plate, zd, vmin=VMIN, vmax=VMAX, backend=b, fields=fields).objective for b in BACKENDS}
    ref = objs["clarabel"]
    for b, v in objs.items():
        assert v == pytest.approx(ref, rel=1e-6), b


def test_input_weight_in_lqr_units_gives_the_lqr_fit(plate, fields):
    zd = plate.target("twist")
    so = static_optimum(plate, zd, fields=fields, backend="direct", input_weight_si=R_DEFAULT)
    u, z = steady_state(plate, zd)
    np.testing.assert_allclose(so.voltages, u, rtol=1e-9, atol=1e-9 * np.abs(u).max())


# -- QP assembly ----------------------------------------------------------------------------------------


def _rollout_cost(pb: TrackingProblem, x0, w_prev, W):
    """The stated cost of an input sequence, evaluated by simulation (independent of the assembly)."""
    X = pb.simulate(x0, W)
    r = pb.reduced.size
    J, wp = 0.0, w_prev
    for x, w in zip(X, W):
        J += pb.stage_shape_cost(x, w) + pb.beta * x[r:] @ x[r:] + pb.rho * w @ w + pb.sigma * np.sum((w - wp) ** 2)
        wp = w
    d = np.r_[X[-1] - pb.x_s, W[-1] - pb.w_s]
    return J + d @ pb.P @ d - pb.lam @ (X[-1] - pb.x_s)


@pytest.mark.parametrize("formulation", ["condensed", "sparse"])
def test_qp_objective_is_the_simulated_cost(problems, formulation):
    pb = problems["bending"]
    N = 12
    qp = assemble_qp(pb, N, formulation)
    rng = np.random.default_rng(3)
    x0 = rng.normal(0, 0.1, pb.nx)
    w_prev = rng.uniform(-0.5, 1.5, pb.m)
    W = rng.uniform(-0.5, 1.5, (N, pb.m))
    v = W.ravel() if formulation == "condensed" else np.r_[W.ravel(), pb.simulate(x0, W).ravel()]
    p = np.r_[x0, w_prev]
    assert qp.objective(v, p) == pytest.approx(_rollout_cost(pb, x0, w_prev, W), rel=1e-10)
    if formulation == "sparse":
        assert np.abs(qp.A_eq @ v - qp.b(p)).max() < 1e-12  # dynamics rows hold on a simulated trajectory


def test_condensed_and_sparse_give_the_same_plan(problems):
    pb = problems["twist"]
    p = np.r_[np.zeros(pb.nx), np.zeros(pb.m)]
    sols = [make_backend("clarabel", assemble_qp(pb, 15, f)).solve(p) for f in ("condensed", "sparse")]
    assert sols[0].objective == pytest.approx(sols[1].objective, rel=1e-7)
    np.testing.assert_allclose(sols[0].v[: 15 * pb.m], sols[1].v[: 15 * pb.m], atol=1e-5)


@pytest.mark.parametrize("formulation", ["condensed", "sparse"])
def test_all_backends_agree_on_the_same_problem(problems, formulation):
    """Must show: objective to 1e-5 relative, every backend, from rest and from a moving state."""
    pb = problems["camber"]
    qp = assemble_qp(pb, 20, formulation)
    rng = np.random.default_rng(7)
    params = [np.zeros(pb.nx + pb.m), np.r_[rng.normal(0, 0.2, pb.nx), pb.w_s * 0.5]]
    for p in params:
        sols = {}
        for name in BACKENDS:
            sols[name] = make_backend(name, qp).solve(p)
        sols["casadi-qp/piqp"] = make_backend("casadi-qp", qp, plugin="piqp").solve(p)
        ref = sols["clarabel"].objective
        for name, sol in sols.items():
            assert sol.status.ok, name
            assert sol.objective == pytest.approx(ref, rel=1e-5), (name, sol.objective, ref)
            assert qp.violation(sol.v, p) < 1e-6, name


def test_plan_respects_voltage_and_slew_limits(problems):
    pb = problems["bending"]
    qp = assemble_qp(pb, 20, "sparse")
    sol = make_backend("clarabel", qp).solve(np.zeros(pb.nx + pb.m))
    W = sol.v[: 20 * pb.m].reshape(20, pb.m)
    tol = 1e-7
    assert W.min() >= pb.w_min.min() - tol and W.max() <= pb.w_max.max() + tol
    steps = np.abs(np.diff(np.vstack([np.zeros(pb.m), W]), axis=0))
    assert steps.max() <= pb.slew + tol
    assert steps.max() >= 0.99 * pb.slew  # from rest towards the limits the slew bound is active


def test_terminal_equality_reaches_the_static_optimum(plate, fields):
    zd = plate.target("camber")
    st = QPSettings(terminal="static", horizon=40)
    pb = TrackingProblem.build(plate, zd, period=0.01, vmin=VMIN, vmax=VMAX, settings=st, fields=fields)
    qp = assemble_qp(pb, 40, "condensed")
    sol = make_backend("clarabel", qp).solve(np.zeros(pb.nx + pb.m))
    W = sol.v.reshape(40, pb.m)
    X = pb.simulate(np.zeros(pb.nx), W)
    np.testing.assert_allclose(X[-1], pb.x_s, atol=1e-6 * np.abs(pb.x_s).max())


def test_infeasible_problem_raises_naming_backend_and_status(problems):
    pb = problems["twist"]
    qp = assemble_qp(pb, 5, "sparse")
    # The previous voltage far outside the limits: the slew bound cannot meet the voltage bound.
    p = np.r_[np.zeros(pb.nx), np.full(pb.m, 10.0)]
    for name in ("clarabel", "osqp", "casadi-qp"):
        with pytest.raises(SolverError) as info:
            make_backend(name, qp).solve(p)
        assert info.value.backend == name
        assert "infeasible" in info.value.status.lower() or "fail" in str(info.value).lower()


# -- steady state -----------------------------------------------------------------------------------


def _affine_law(ctrl, p0, delta=1e-2):
    """The receding-horizon law ``w = K p + k`` where no limit is active, from ``n_p + 1`` solves at ``p0 + delta e_i``.

    (Away from every limit the QP's minimiser is affine in ``p``, so differences are exact.)
    """
    be = ctrl.backend
    w0 = be.solve(p0).v[: ctrl.problem.m]
    K = np.column_stack([(be.solve(p0 + delta * e).v[: ctrl.problem.m] - w0) / delta for e in np.eye(p0.size)])
    return K, w0 - K @ p0


@pytest.mark.parametrize("shape", SHAPES)
def test_without_active_limits_the_steady_state_is_the_unconstrained_optimum(plate, fields, shape):
    """Must show: very wide bounds -> the QP's steady state equals the unconstrained optimum (1e-6),
    which with the LQR's input weight is the LQR's steady shape."""
    zd = plate.target(shape)
    ctrl = make_qp_controller(
        plate, zd, vmin=-1e6, vmax=1e6, period=0.01, input_weight_si=R_DEFAULT, horizon=10, solver="casadi-qp",
        offset_free=False,  # the law of p = (x, w_prev); offset-free's steady state: test_control_plant_mismatch
    )  # fmt: skip
    pb = ctrl.problem
    u_free, z_lqr = steady_state(plate, zd)  # R-regularised unconstrained fit (= LQR's steady state)
    # Near its steady state no limit (voltage or slew) is active and the QP is an affine feedback law
    # w = K (x, w_prev) + k; the loop's fixed point follows from that law, whatever point it was taken at.
    rng = np.random.default_rng(0)
    p0 = np.r_[pb.x_s, pb.w_s] * (1 + 0.05 * rng.standard_normal(pb.nx + pb.m))
    K, k = _affine_law(ctrl, p0)
    Acl = np.block([[pb.F + pb.G @ K[:, : pb.nx], pb.G @ K[:, pb.nx :]], [K[:, : pb.nx], K[:, pb.nx :]]])
    assert np.abs(np.linalg.eigvals(Acl)).max() < 1.0  # the loop is stable: its fixed point is reached
    xi = np.linalg.solve(np.eye(pb.nx + pb.m) - Acl, np.r_[pb.G @ k, k])
    u_ss = 1000.0 * xi[pb.nx :]
    assert np.abs(u_ss - u_free).max() <= 1e-6 * np.abs(u_free).max()
    z_ss = fields @ u_ss
    assert plate.m_norm(z_ss - z_lqr) <= 1e-6 * plate.m_norm(z_lqr)


def test_limits_pull_the_steady_state_to_the_static_optimum(problems):
    # With active limits the receding-horizon fixed point is the static optimum (not the clipped LQR fit).
    pb = problems["bending"]
    be = make_backend("casadi-qp", assemble_qp(pb, 20, "condensed"))
    sol = be.solve(np.r_[pb.x_s, pb.w_s])
    np.testing.assert_allclose(sol.v[: pb.m], pb.w_s, atol=1e-7)


def test_warm_start_shift_keeps_the_plan_shape(problems):
    pb = problems["twist"]
    for form in ("condensed", "sparse"):
        qp = assemble_qp(pb, 6, form)
        v = np.arange(qp.n_variables, dtype=float)
        s = _shift(v, qp)
        assert s.shape == v.shape
        np.testing.assert_array_equal(s[: pb.m], v[pb.m : 2 * pb.m])


def test_settings_are_validated():
    with pytest.raises(InputError, match="solver = 'gurobi'"):
        QPSettings(solver="gurobi")
    with pytest.raises(InputError, match="mode"):
        QPSettings(mode="sideways")
    with pytest.raises(InputError, match="horizon"):
        QPSettings(horizon=0)


def test_unknown_factory_option_is_named(plate):
    with pytest.raises(InputError, match="qp option.*colour"):
        make_qp_controller(plate, plate.target("twist"), vmin=VMIN, vmax=VMAX, period=0.01, colour="red")


def test_parametric_qp_checks_shapes():
    with pytest.raises(InputError, match="do not agree"):
        ParametricQP(
            H=sp.identity(3, format="csc"),
            q0=np.zeros(3),
            Qp=sp.csc_matrix((3, 1)),
            A_in=sp.identity(2, format="csc"),
            l0=np.zeros(2),
            Lp=sp.csc_matrix((2, 1)),
            u0=np.ones(2),
            Up=sp.csc_matrix((2, 1)),
        )
