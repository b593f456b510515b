"""Sensor design (issue 13): information against finite differences, relaxation bound against brute
force, monotone greedy/swaps, the risk criterion's parts, TOML round trips and bad input."""

from __future__ import annotations

import itertools
import tomllib

import numpy as np
import pytest

from wingopt.design.candidates import candidate_grid, parse_candidates
from wingopt.design.criteria import LinearCriterion
from wingopt.design.information import InformationSettings, ModalSensitivity
from wingopt.design.priors import gp_prior, smooth_loads, tikhonov_prior
from wingopt.design.risk import BayesRisk
from wingopt.design.selection import greedy, overlap_matrix, random_layouts, relax, round_weights, swap_improve
from wingopt.errors import InputError
from wingopt.membrane import MembraneModel, StretchSensors, load_case
from wingopt.problem import load_problem, read_problem_table
from wingopt.problem.membrane import StretchSensorSpec
from wingopt.problem.toml_text import problem_text, sensors_text


@pytest.fixture(scope="module")
def small():
    """13x7 membrane, 12 modes, 4 state modes, 60 ms record: small enough for brute force."""
    prob = load_problem("membrane").with_mesh((13, 7))
    model = MembraneModel.from_problem(prob.with_sensors(()))
    sens = ModalSensitivity.from_model(model, InformationSettings(modes=12, state_modes=4, t_end=0.06, window_s=0.02))
    return prob, model, sens


def test_lattice_sensor_matrices_match_assembly(small):
    prob, model, sens = small
    hx = prob.width / 24
    rects = np.array([[2 * hx, 8 * hx, prob.height / 12, 5 * prob.height / 12], [0.01, 0.045, 0.01, 0.022]])
    chat = sens.modal_matrices(rects)
    for r, C in zip(rects, chat):
        S = StretchSensors.assemble(model.space, [StretchSensorSpec("a", tuple(r))])
        ref = sens.shapes.T @ (S.matrices[0] @ sens.shapes)
        assert np.abs(C - ref).max() <= 1e-12 * np.abs(ref).max()
    assert sens.lattice_index(rects[:1]) is not None and sens.lattice_index(rects[1:]) is None


def _outputs(sens, chat, theta):
    """Sensor outputs by plain simulation of the modal ZOH recursion (independent of ``seq``)."""
    ms, m = sens.settings.state_modes, sens.m
    q0 = np.zeros(m)
    qd0 = np.zeros(m)
    q0[:ms], qd0[:ms], u = theta[:ms], theta[ms : 2 * ms], theta[2 * ms :]
    disc = sens.model.modal(m).discretize(sens.dt)
    F, g = disc.F, disc.g
    Q = [q0]
    q, qd = q0, qd0
    for _ in range(sens.steps):
        q, qd = F[:, 0, 0] * q + F[:, 0, 1] * qd + g[:, 0] * u, F[:, 1, 0] * q + F[:, 1, 1] * qd + g[:, 1] * u
        Q.append(q)
    Q = np.array(Q)
    return np.einsum("ti,cij,tj->tc", Q, chat, Q)


def test_information_matches_finite_differences(small):
    prob, model, sens = small
    chat = sens.modal_matrices(np.array([[0.02, 0.06, 0.01, 0.03], [0.07, 0.12, 0.035, 0.06]]))
    ms = sens.settings.state_modes
    q0 = sens.initial_state()
    q0[ms:] = 0.0  # the nuisance unknowns are the low modes' initial state
    u = sens.modal_load(model.project(load_case("L1", prob.width, prob.height)))
    theta = np.concatenate([q0[:ms], np.zeros(ms), u])
    base = _outputs(sens, chat, theta)
    J_fd = np.empty((base.shape[0], 2, theta.size))
    for k in range(theta.size):
        h = 1e-6 * max(abs(theta[k]), np.abs(theta).max() * 1e-3)
        e = np.zeros_like(theta)
        e[k] = h
        J_fd[:, :, k] = (_outputs(sens, chat, theta + e) - _outputs(sens, chat, theta - e)) / (2 * h)
    q = sens.response(u, q0)
    J = sens.jacobian(chat, q)  # (2, T+1, d)
    err = np.abs(J.transpose(1, 0, 2) - J_fd).max() / np.abs(J_fd).max()
    assert err < 1e-6
    info = sens.information(chat, u, q0, noise_fraction=0.01)
    sigma = 0.01 * np.abs(base).max(axis=0)
    for i in range(2):
        Jn = J_fd[:, i] / sigma[i]
        ref = Jn.T @ Jn
        assert np.abs(info.total[i] - ref).max() < 1e-5 * np.abs(ref).max()
    nw = sens.window_samples
    Jw = J_fd[:nw, 0] / sigma[0]
    assert np.allclose(info.window[0], Jw.T @ Jw, rtol=1e-5, atol=1e-5 * np.abs(Jw.T @ Jw).max())


@pytest.fixture(scope="module")
def tiny(small):
    """8 candidates, 2 nominal loads, GP prior: the A and D criteria."""
    prob, model, sens = small
    cands = candidate_grid(prob, sizes=[(0.035, 0.0175)], step=3)
    idx = np.linspace(0, len(cands) - 1, 8).astype(int)
    rects = cands.rects[idx]
    chat = sens.modal_matrices(rects)
    q0 = sens.initial_state()
    loads = smooth_loads(prob.width, prob.height, 2, seed=3)
    infos = [sens.information(chat, sens.modal_load(model.project(P)), q0) for P in loads]
    prior = gp_prior(model, 0.3 * prob.width, 200.0)
    return sens, rects, infos, loads, prior, q0


@pytest.mark.parametrize("kind", ["a", "lift", "d"])
def test_relaxation_bound_below_every_subset(tiny, kind):
    sens, rects, infos, loads, prior, q0 = tiny
    crit = LinearCriterion.build(kind, sens, infos, prior, q0)
    K = 3
    rel = relax(crit, K, rank=sens.dim)  # no reduction: the bound is exact for the criterion
    assert rel.dropped == 0.0
    values = [crit.value(list(c)) for c in itertools.combinations(range(crit.count), K)]
    assert rel.bound <= min(values) + 1e-6 * abs(min(values))
    assert abs(np.sum(rel.weights) - K) < 1e-5
    # the bound is not trivial: above the criterion of all 8 candidates together
    assert rel.bound >= crit.value(list(range(crit.count))) - 1e-6 * abs(min(values))


def test_greedy_and_swaps_are_monotone(tiny):
    sens, rects, infos, loads, prior, q0 = tiny
    crit = LinearCriterion.build("a", sens, infos, prior, q0)
    layout, path = greedy(crit, 3)
    assert np.all(np.diff(path) <= 1e-12)  # adding information never hurts the A-criterion
    worst = max(itertools.combinations(range(crit.count), 3), key=lambda c: crit.value(list(c)))
    best_layout, spath = swap_improve(crit, list(worst))
    assert np.all(np.diff(spath) < 0) and spath[-1] <= crit.value(list(worst))
    assert abs(spath[-1] - crit.value(best_layout)) < 1e-12
    brute = min(crit.value(list(c)) for c in itertools.combinations(range(crit.count), 3))
    assert spath[-1] <= 1.05 * brute
    risk = BayesRisk.build(sens, infos, loads, q0)
    _, rpath = swap_improve(risk, list(worst))
    assert np.all(np.diff(rpath) < 0)


def test_round_weights_skips_overlaps():
    rects = np.array([[0, 2, 0, 1], [1, 3, 0, 1], [4, 5, 0, 1]], dtype=float)
    ov = overlap_matrix(rects)
    assert ov[0, 1] and not ov[0, 2]
    assert list(round_weights(np.array([0.9, 0.8, 0.3]), 2, ov)) == [0, 2]
    with pytest.raises(InputError, match="non-overlapping"):
        round_weights(np.array([0.9, 0.8, 0.3]), 3, ov)


def test_risk_terms_and_rule(tiny, small):
    """Bias + noise of the linearised Tikhonov estimate against a direct dense computation."""
    sens, rects, infos, loads, prior, q0 = tiny
    prob, model, _ = small
    risk = BayesRisk.build(sens, infos, loads, q0)
    layout = [0, 3, 6]
    c, lams = risk.estimate(layout)
    # direct: f^ = (B^T H B + lam Lam)^-1 B^T H B f with H the Schur complement on u
    F = risk.layout_sum(layout)[0, 1]
    k = risk.ms2
    H = F[k:, k:] - F[k:, :k] @ np.linalg.solve(F[:k, :k] + np.eye(k), F[:k, k:])
    B = sens.input_matrix
    Lam = model.regularizer.toarray()
    f = model.project(loads[0])
    A = B.T @ H @ B
    fhat = np.linalg.solve(A + lams[0] * Lam, A @ f)
    assert np.allclose(risk.load_coefficients(layout)[0], fhat, rtol=1e-6, atol=1e-8 * np.abs(fhat).max())
    M = model.gram.toarray()
    Cov = np.linalg.solve(A + lams[0] * Lam, A) @ np.linalg.inv(A + lams[0] * Lam)
    from wingopt.fe import integrate

    norm2 = integrate(model.space, lambda x, y: loads[0](x, y) ** 2, order=8)
    rep = norm2 - f @ M @ f
    e = f - fhat
    direct = np.sqrt((rep + e @ M @ e + np.trace(M @ Cov)) / norm2)
    got = risk.per_nominal(risk.layout_sum(layout)[None], 3)[0, 0]
    assert abs(got - direct) < 1e-6 * direct
    assert np.all(lams > 0)


def test_tikhonov_prior_is_the_regulariser(small):
    prob, model, sens = small
    pr = tikhonov_prior(model, 2.0)
    assert np.allclose(np.linalg.inv(pr.cov), 2.0 * model.regularizer.toarray(), rtol=1e-6, atol=1e-6)
    with pytest.raises(InputError, match="lambda"):
        tikhonov_prior(model, 0.0)


def test_candidates_spec_and_keepout():
    prob = load_problem("membrane")
    c = parse_candidates("sizes=0.035x0.0117;step=2;keepout=0.06:0.08:0:0.07;rect=0.01:0.02:0.01:0.02", prob)
    assert len(c) > 50
    mid = (c.rects[:, 0] < 0.08) & (c.rects[:, 1] > 0.06)
    assert not mid.any()
    assert c.find((0.01, 0.02, 0.01, 0.02)) is not None
    for bad, msg in [
        ("sizes=abc", "sizes="),
        ("step=0", "step"),
        ("keepout=1:2", "four numbers"),
        ("colour=red", "expected sizes="),
        ("keepout=0:0.14:0:0.07", "none left"),
        ("sizes=0.5x0.01", "larger than"),
    ]:
        with pytest.raises(InputError, match=msg):
            parse_candidates(bad, prob)


def test_problem_text_round_trip():
    from wingopt.problem import PROBLEMS_DIR

    table = read_problem_table(PROBLEMS_DIR / "membrane.toml")
    rects = [[0.01, 0.04, 0.02, 0.03], [0.1, 0.13, 0.04, 0.0525]]
    back = tomllib.loads(problem_text(table, rects, header="designed\nsecond line"))
    want = dict(table)
    want["sensors"] = [{"name": f"S{i + 1}", "rect": r} for i, r in enumerate(rects)]
    assert back == want
    odd = {"a": {"key with space": 'q"uote\\', "x": [1, 2.5e-7, True]}, "sensors": []}
    assert tomllib.loads(problem_text(odd, rects))["a"] == odd["a"]
    pasted = tomllib.loads(sensors_text(rects, header="h"))
    assert pasted["sensors"][1]["rect"] == rects[1]


def test_design_bad_input():
    from wingopt.design import design_sensors

    prob = load_problem("membrane")
    with pytest.raises(InputError, match="count"):
        design_sensors(prob, 0)
    with pytest.raises(InputError, match="criterion"):
        design_sensors(prob, 2, criterion="e")
    with pytest.raises(InputError, match="more than"):
        design_sensors(prob, 10, "only-rects")
    with pytest.raises(InputError, match="membrane"):
        design_sensors(load_problem("plate") if _has_plate() else object(), 2)


def _has_plate() -> bool:
    from wingopt.problem import builtin_problems

    return "plate" in builtin_problems()


def test_random_layouts_are_non_overlapping_k_subsets_of_the_pool():
    # a 4 x 3 grid of unit cells and 6 shifted cells overlapping them
    cells = [(x, x + 1, y, y + 1) for x in range(4) for y in range(3)]
    shifted = [(x + 0.5, x + 1.5, y + 0.5, y + 1.5) for x in range(3) for y in range(2)]
    rects = np.array(cells + shifted, dtype=float)
    pool = np.arange(2, len(rects))
    lays = random_layouts(rects, 3, 25, np.random.default_rng(0), pool)
    ov = overlap_matrix(rects)
    assert len(lays) == 25 and len({tuple(sorted(x)) for x in lays}) > 10
    for lay in lays:
        assert len(set(lay)) == 3 and set(lay) <= set(pool)
        assert not ov[np.ix_(lay, lay)][~np.eye(3, dtype=bool)].any()
    again = random_layouts(rects, 3, 25, np.random.default_rng(0), pool)
    assert all(np.array_equal(a, b) for a, b in zip(lays, again))
