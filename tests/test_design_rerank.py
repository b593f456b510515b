"""Monte Carlo re-ranking (issue 13): the short list's invariants, scores equal to the estimator's own
runs, the winner is the lowest score, and the named design-time loads."""

from __future__ import annotations

import numpy as np
import pytest

from wingopt.design import DesignSettings, InformationSettings, design_sensors
from wingopt.design.montecarlo import IdentifyTask, named_load, run_task
from wingopt.design.priors import smooth_loads
from wingopt.design.rerank import MonteCarloSettings, rerank, shortlist
from wingopt.design.selection import overlap_matrix
from wingopt.errors import InputError
from wingopt.problem import load_problem


@pytest.fixture(scope="module")
def small_design():
    """K = 2 on a 13x7 membrane, A-criterion, coarse candidates: a swap local optimum."""
    prob = load_problem("membrane").with_mesh((13, 7))
    info = InformationSettings(modes=12, state_modes=4, t_end=0.06, window_s=0.02)
    s = DesignSettings(criterion="a", information=info, nominal_count=2, rank=6)
    return prob, design_sensors(prob, 2, "sizes=0.035x0.0175;step=3", s)


def test_shortlist_invariants(small_design):
    prob, res = small_design
    lays = shortlist(res, 6)
    assert len(lays) == 6
    assert np.array_equal(lays[0], res.layout)
    keys = {tuple(sorted(lay)) for lay in lays}
    assert len(keys) == 6  # distinct
    ov = overlap_matrix(res.candidates.rects)
    for lay in lays:
        assert not ov[lay[0], lay[1]]  # no overlapping sensors
    # the design is a 1-swap local optimum: no neighbour on the list scores below it
    neighbours = [lay for lay in lays[1:] if len(set(lay) & set(res.layout)) == 1]
    assert neighbours
    assert all(res.linear.value(lay) >= res.value - 1e-12 for lay in neighbours)


def test_rerank_scores_are_the_estimators_errors(small_design):
    prob, res = small_design
    s = MonteCarloSettings(loads=("smooth:7:0:0.2",), seeds=(100, 101), shortlist=2, t_end=0.1, truth_nodes=(25, 13))
    rr = rerank(res, s)
    assert len(rr.layouts) == 2 and len(rr.records) == 4
    assert rr.best == int(np.argmin(rr.scores))
    # each score is the mean of independent runs of the estimator on the same tasks
    for i, lay in enumerate(rr.layouts):
        rects = tuple(tuple(float(v) for v in r) for r in res.candidates.rects[lay])
        errs = [
            run_task(IdentifyTask(prob, rects, "smooth:7:0:0.2", 0.01, seed, (25, 13), None, 0.1))["load_error"]
            for seed in (100, 101)
        ]
        assert rr.scores[i] == pytest.approx(np.mean(errs), rel=1e-9)
        assert rr.spread[i] == pytest.approx(np.std(errs, ddof=1) / np.sqrt(2), rel=1e-6)
        assert 0.0 < rr.scores[i] < 2.0
    assert rr.summary()["best"] == rr.best


def test_named_design_time_loads():
    prob = load_problem("membrane")
    W, H = prob.width, prob.height
    x, y = np.meshgrid(np.linspace(0, W, 7), np.linspace(0, H, 5))
    ref = smooth_loads(W, H, 3, 7, 0.2 * W)[2](x, y)
    assert np.array_equal(named_load("smooth:7:2:0.2", W, H)(x, y), ref)
    # without a length: the 0.3-chord family (the held-out loads' default)
    assert np.array_equal(named_load("smooth:5:1", W, H)(x, y), smooth_loads(W, H, 2, 5)[1](x, y))
    for bad in ("smooth:7", "smooth:7:1:0", "smooth:7:-1", "smooth:7:1:0.2:3", "wavy"):
        with pytest.raises(InputError, match="load ="):
            named_load(bad, W, H)
    with pytest.raises(InputError, match="shortlist"):
        MonteCarloSettings(shortlist=0)


def test_adopt_redoes_the_predictions(small_design):
    prob, res_a = small_design
    from wingopt.design.rerank import Reranked, adopt

    with pytest.raises(InputError, match="risk"):
        adopt(res_a, Reranked([res_a.layout], np.zeros(1), np.zeros(1), np.zeros(1), 0, []))
    info = InformationSettings(modes=12, state_modes=4, t_end=0.06, window_s=0.02)
    res = design_sensors(
        prob, 2, "sizes=0.035x0.0175;step=3", DesignSettings(information=info, nominal_count=2, rank=6)
    )
    lays = shortlist(res, 3)
    fake = Reranked(lays, np.array([res.risk.value(x) for x in lays]), np.array([0.5, 0.4, 0.6]), np.zeros(3), 1, [])
    new = adopt(res, fake)
    assert np.array_equal(new.layout, lays[1]) and np.array_equal(res.layout, lays[0])  # a copy
    assert new.value == pytest.approx(res.risk.value(lays[1])) and new.value >= res.value - 1e-12
    assert new.predictions["risk_relative_load_error"] == pytest.approx(new.value)
    assert new.predictions["montecarlo_relative_load_error"] == 0.4
    rel = new.relaxation
    assert rel["bound"] == res.relaxation["bound"] and rel["chosen_reduced"] >= rel["bound"] - 1e-9
    assert new.baselines["montecarlo"]["best"] == 1


def test_edge_loads_shape():
    from wingopt.design.priors import edge_loads

    prob = load_problem("membrane")
    W, H = prob.width, prob.height
    loads = edge_loads(W, H, 6, 9)
    assert len({P.description.split(",")[0] for P in loads}) >= 2  # more than one edge drawn
    for k, P in enumerate(loads):
        pts = (np.array([0.0, 0.03, 0.1]), np.array([0.02, 0.0, 0.05]))
        assert np.array_equal(named_load(f"edge:9:{k}", W, H)(*pts), P(*pts))
        where = P.description.split(",")[0].replace("edge-heavy at ", "")
        edge = ("x = 0", "x = W", "y = 0", "y = L").index(where)
        span = W if edge < 2 else H
        # the envelope along the normal of its edge: 1 on the edge, exponential (env(2t) = env(t)^2),
        # with a decay length delta * span, delta in [0.1, 0.4]
        g = smooth_loads(W, H, k + 1, 9 + 7919, 0.2 * W, mean=0.0, spread=1.0, amplitude=1.0)[k]
        t = np.array([0.0, 0.1, 0.2]) * span
        x, y = [(t, 0.5 * H + 0 * t), (W - t, 0.5 * H + 0 * t), (0.5 * W + 0 * t, t), (0.5 * W + 0 * t, H - t)][edge]
        env = P(x, y) / (200.0 * (1.0 + 0.5 * g(x, y)))
        assert env[0] == pytest.approx(1.0, rel=1e-12) and env[2] == pytest.approx(env[1] ** 2, rel=1e-9)
        assert 0.1 <= -0.1 / np.log(env[1]) <= 0.4
    with pytest.raises(InputError, match="load ="):
        named_load("edge:9", W, H)
