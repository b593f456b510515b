"""The optimisation layer: every QP backend on the same parametric QPs, the registry, the layering."""

import ast
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from wingopt.cli import solver_flag_hint
from wingopt.errors import InputError, SolverError
from wingopt.optim import (
    BACKENDS,
    ParametricQP,
    SolveStatus,
    available_backends,
    check_solver,
    default_backend,
    make_backend,
    registry,
    solver_names,
)
from wingopt.optim.least_distance import LDP_SOLVERS, LeastDistanceQP
from wingopt.optim.qp import DenseForm
from wingopt.optim.status import status_from

ROOT = Path(__file__).resolve().parents[1]


def _random_qp(seed=0, n=12, n_par=3, with_eq=True, cond=1e6):
    """A strictly convex QP with box rows first, general rows, an equality and a parameter in all of them."""
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    H = Q @ np.diag(np.logspace(0, np.log10(cond), n)) @ Q.T
    G = rng.standard_normal((4, n))
    A_in = sp.vstack([sp.identity(n), sp.csc_matrix(G)], format="csc")
    l0 = np.r_[np.full(n, -0.3), np.full(4, -1.0)]
    u0 = np.r_[np.full(n, 0.5), np.full(4, 1.0)]
    Lp = sp.csc_matrix(0.1 * rng.standard_normal((n + 4, n_par)))
    kw = {}
    if with_eq:
        kw = dict(
            A_eq=sp.csc_matrix(rng.standard_normal((1, n))),
            b0=np.array([0.05]),
            Bp=sp.csc_matrix(np.ones((1, n_par)) * 0.01),
        )
    return ParametricQP(
        H=sp.csc_matrix(0.5 * (H + H.T)),
        q0=rng.standard_normal(n) * cond**0.5,
        Qp=sp.csc_matrix(rng.standard_normal((n, n_par))),
        A_in=A_in,
        l0=l0,
        Lp=Lp,
        u0=u0,
        Up=Lp.copy(),
        c0=1.0,
        **kw,
    )


@pytest.mark.parametrize("with_eq", [False, True])
def test_every_installed_backend_agrees_on_the_same_qp(with_eq):
    """Objective to 1e-6 relative of Clarabel's and bounds within 1e-6: not only a status."""
    qp = _random_qp(with_eq=with_eq)
    params = [np.zeros(3), np.array([0.5, -1.0, 2.0])]
    for name in available_backends():
        be = make_backend(name, qp)
        for p in params:
            ref = make_backend("clarabel", qp).solve(p)
            sol = be.solve(p)
            assert sol.status.ok and sol.backend == name
            assert sol.objective == pytest.approx(ref.objective, rel=1e-6, abs=1e-8), name
            assert qp.violation(sol.v, p) < 1e-6, name
            # Active constraints exist (else the test would not test the bounds).
            assert np.any(
                np.isclose(qp.A_in @ ref.v, qp.upper(p), atol=1e-6)
                | np.isclose(qp.A_in @ ref.v, qp.lower(p), atol=1e-6)
            )


def test_daqp_keeps_its_active_set_between_solves():
    qp = _random_qp(with_eq=False)
    be = make_backend("daqp", qp)
    p = np.array([0.2, 0.1, -0.3])
    first = be.solve(p)
    again = be.solve(p)  # same data: the kept active set is already optimal
    assert first.iterations >= 2 and again.iterations <= 1
    np.testing.assert_allclose(again.v, first.v, atol=1e-12)


def test_dense_form_takes_the_leading_identity_rows_as_simple_bounds():
    qp = _random_qp(with_eq=True)
    d = DenseForm(qp)
    assert d.n_bounds == qp.n_variables and d.A.shape == (4, qp.n_variables)
    lo, hi = d.bounds(np.ones(3))
    np.testing.assert_allclose(lo, qp.lower(np.ones(3)))
    np.testing.assert_allclose(hi, qp.upper(np.ones(3)))


@pytest.mark.parametrize("name", ["daqp", "piqp", "proxqp", "clarabel"])
def test_infeasible_qp_raises_naming_backend_status_and_hint(name):
    if name not in available_backends():
        pytest.skip(f"{name} not installed")
    qp = _random_qp(with_eq=False)
    bad = ParametricQP(qp.H, qp.q0, qp.Qp, qp.A_in, qp.l0 + 10.0, qp.Lp, qp.u0, qp.Up)  # lower above upper
    with pytest.raises(SolverError) as exc:
        make_backend(name, bad).solve(np.zeros(3))
    assert exc.value.backend == name
    failed = (SolveStatus.INFEASIBLE, SolveStatus.NUMERICAL_ERROR, SolveStatus.MAX_ITERATIONS)
    assert status_from(name, exc.value.status) in failed
    assert exc.value.context == "qp" and "another QP backend" in str(exc.value)
    assert "--" not in str(exc.value)  # the optimisation layer names no flag; the CLI adds it
    assert solver_flag_hint("morph", exc.value) == f" (--solver {'|'.join(available_backends())})"


@pytest.mark.parametrize(
    "raw,expected",
    [
        ("solved", SolveStatus.OPTIMAL),  # DAQP 1, PIQP, ProxQP
        ("cycling", SolveStatus.NUMERICAL_ERROR),  # DAQP -2
        ("max iterations reached", SolveStatus.MAX_ITERATIONS),  # DAQP -4
        ("nonconvex problem", SolveStatus.NUMERICAL_ERROR),  # DAQP -5
        ("primal_infeasible", SolveStatus.INFEASIBLE),  # PIQP, ProxQP
        ("dual_infeasible", SolveStatus.UNBOUNDED),
        ("max_iter_reached", SolveStatus.MAX_ITERATIONS),
        ("numerics", SolveStatus.NUMERICAL_ERROR),
    ],
)
def test_status_words_of_the_dense_solvers(raw, expected):
    assert status_from("daqp", raw) is expected


def test_registry_names_and_default():
    assert set(available_backends()) <= set(BACKENDS)
    assert {"clarabel", "osqp", "ipopt", "casadi-qp"} <= set(available_backends())  # always installed
    assert default_backend() == ("daqp" if "daqp" in available_backends() else "clarabel")
    with pytest.raises(InputError, match="solver = 'gurobi'"):
        make_backend("gurobi", _random_qp())


def test_one_vocabulary_of_solver_names():
    """Every consumer's names are a capability of the registry; every refusal lists them."""
    from wingopt.control.mpc_settings import QPSettings
    from wingopt.estimation.mhe import MHESettings
    from wingopt.estimation.mhe.solvers import WINDOW_SOLVERS, make_solver

    assert BACKENDS == solver_names("qp") == ("daqp", "clarabel", "osqp", "piqp", "proxqp", "ipopt", "casadi-qp")
    assert LDP_SOLVERS == solver_names("least-distance") == ("daqp", "clarabel", "osqp")
    assert WINDOW_SOLVERS == solver_names("window") == ("numpy", "cvxpy", "ipopt")
    assert solver_names("sdp") == ("clarabel", "scs")
    assert all(registry.SOLVERS[name].backend is not None for name in BACKENDS)
    refusals = [
        (lambda: QPSettings(solver="gurobi"), BACKENDS),
        (lambda: MHESettings(backend="gurobi"), WINDOW_SOLVERS),
        (lambda: MHESettings(qp_solver="gurobi"), LDP_SOLVERS),
        (lambda: make_solver("gurobi"), WINDOW_SOLVERS),
        (lambda: check_solver("gurobi", "sdp", "relaxation solver"), solver_names("sdp")),
    ]
    for refuse, names in refusals:
        with pytest.raises(InputError, match="'gurobi'") as exc:
            refuse()
        assert ", ".join(names) in str(exc.value)
    assert check_solver("Clarabel", "sdp") == "clarabel"


def test_a_missing_package_is_named(monkeypatch):
    monkeypatch.setattr(registry, "_installed", lambda name: name != "piqp")
    with pytest.raises(InputError, match="package 'piqp' is not installed"):
        registry.backend_class("piqp")
    assert "piqp" not in registry.available_backends()
    monkeypatch.setattr(registry, "_installed", lambda name: name not in ("daqp",))
    assert registry.default_backend() == "clarabel"


def test_least_distance_solvers_agree():
    rng = np.random.default_rng(4)
    n = 8
    c = rng.standard_normal(n)
    M = rng.standard_normal((5, n))
    lo, hi = np.full(5, -0.2), np.full(5, 0.2)
    sols = {}
    for solver in LDP_SOLVERS:
        if solver in ("daqp",) and "daqp" not in available_backends():
            continue
        sols[solver] = LeastDistanceQP(solver).solve(c, M, lo, hi)
    ref = sols["clarabel"]
    assert np.max(M @ ref - hi) < 1e-7 and np.max(lo - M @ ref) < 1e-7
    assert np.linalg.norm(ref - c) > 0.1  # the bounds bind
    for solver, z in sols.items():
        np.testing.assert_allclose(z, ref, atol=1e-5, err_msg=solver)
    np.testing.assert_array_equal(LeastDistanceQP("daqp").solve(c), c)  # no constraint: z = c
    with pytest.raises(SolverError) as exc:
        LeastDistanceQP("clarabel", label="cvxpy-clarabel").solve(
            c, np.vstack([M[:1], M[:1]]), [1.0, -3.0], [2.0, -2.0]
        )
    assert exc.value.backend == "cvxpy-clarabel" and exc.value.context == "mhe"
    assert solver_flag_hint("identify", exc.value) == " (--solver numpy|cvxpy|ipopt)"
    with pytest.raises(InputError, match="qp_solver = 'piqp': expected one of daqp, clarabel, osqp"):
        LeastDistanceQP("piqp")


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return out
