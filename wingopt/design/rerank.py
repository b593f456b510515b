"""Monte Carlo re-ranking: a design's short list scored by the real estimator on design-time loads.

The linearised criteria (:mod:`~wingopt.design.risk`, :mod:`~wingopt.design.criteria`) rank
layouts cheaply but do not see what the nonlinear estimator does (local minima, sign errors, the
data-driven weight on an actual record). The Monte Carlo criterion does: the mean relative load
error of the package's MHE over a set of prior loads and noise seeds, each one identification
(:class:`~wingopt.design.montecarlo.IdentifyTask`). It costs about 0.3–0.7 s of CPU per
identification, so it is applied to a short list only:

1. :func:`shortlist` — the designed layout, the design's greedy and rounded starts, and the
   layouts one swap away from the design that the criterion ranks best (distinct, non-overlapping);
2. :func:`rerank` — the Monte Carlo criterion of each, the lowest wins.

The prior loads are those of the design itself (draws of its nominal GP family, named
``smooth:SEED:K:ELL``), never the loads a layout is later validated on. The map over the tasks is
the caller's: serial (default), a process pool, or the study engine (``wingopt.workflows.sweep``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wingopt.design.montecarlo import IdentifyTask, run_tasks
from wingopt.errors import InputError

__all__ = ["MonteCarloSettings", "Reranked", "shortlist", "monte_carlo_scores", "rerank", "adopt"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MonteCarloSettings:
    """The Monte Carlo criterion.

    Parameters
    ----------
    loads : tuple of str
        Prior loads (names of :func:`~wingopt.design.montecarlo.named_load`); default: the first
        four draws of the design's nominal family (GP length 0.2 chord, seed 7).
    seeds : tuple of int
        Noise seeds of each load.
    shortlist : int
        Layouts scored (the design's own included).
    noise_fraction, t_end, truth_nodes
        Noise (0.01 = 1 % of each sensor's peak), record length (s) and mesh of the simulated truth.
    """

    loads: tuple[str, ...] = tuple(f"smooth:7:{k}:0.2" for k in range(4))
    seeds: tuple[int, ...] = (100, 101)
    shortlist: int = 8
    noise_fraction: float = 0.01
    t_end: float = 0.3
    truth_nodes: tuple[int, int] = (49, 25)

    def __post_init__(self):
        if not self.loads:
            raise InputError("montecarlo loads = (): expected at least one load name")
        if not self.seeds:
            raise InputError("montecarlo seeds = (): expected at least one noise seed")
        if not (isinstance(self.shortlist, int) and self.shortlist >= 1):
            raise InputError(f"montecarlo shortlist = {self.shortlist!r}: expected a positive integer")


@dataclass(frozen=True)
class Reranked:
    """Short-listed layouts (candidate indices), their criterion values and Monte Carlo scores."""

    layouts: list[np.ndarray]
    predicted: np.ndarray
    scores: np.ndarray  # mean relative load error over loads x seeds
    spread: np.ndarray  # standard error of each score
    best: int  # index into ``layouts``
    records: list[dict]

    def summary(self) -> dict:
        return {
            "layouts": [lay.tolist() for lay in self.layouts],
            "predicted": self.predicted.tolist(),
            "montecarlo": self.scores.tolist(),
            "montecarlo_stderr": self.spread.tolist(),
            "best": self.best,
            "identifications": len(self.records),
        }


def shortlist(result, size: int) -> list[np.ndarray]:
    """The design's layout, its starts, and its best-ranked 1-swap neighbours: ``size`` distinct layouts."""
    crit = result.risk if result.settings.criterion == "risk" else result.linear
    best = [int(i) for i in result.layout]
    K = len(best)
    from wingopt.design.selection import _evaluate, overlap_matrix

    ov = None if result.settings.allow_overlap else overlap_matrix(result.candidates.rects)
    out: list[np.ndarray] = [np.array(best)]
    seen = {tuple(sorted(best))}
    for name in ("greedy", "relaxation_rounded"):
        lay = result.baselines.get(name, {}).get("layout")
        if lay is not None and tuple(sorted(lay)) not in seen and len(out) < size:
            out.append(np.array(lay))
            seen.add(tuple(sorted(lay)))
    # every 1-swap neighbour of the design, ranked by the design criterion
    neigh, vals = [], []
    for k in range(K):
        others = best[:k] + best[k + 1 :]
        base = crit.layout_sum(others)
        free = np.ones(crit.count, bool)
        free[best] = False
        if ov is not None:
            free &= ~ov[others].any(axis=0)
        cand = np.flatnonzero(free)
        if cand.size == 0:
            continue
        vals.append(_evaluate(crit, base, cand, K))  # chunked: the dense sums of all N would not fit
        neigh += [others[:k] + [int(c)] + others[k:] for c in cand]
    if neigh:
        for j in np.argsort(np.concatenate(vals)):
            if len(out) >= size:
                break
            key = tuple(sorted(neigh[j]))
            if key not in seen:
                out.append(np.array(neigh[j]))
                seen.add(key)
    return out


def monte_carlo_scores(
    problem, layouts_rects: list[np.ndarray], settings: MonteCarloSettings, mapper: Callable | None = None
) -> tuple[np.ndarray, np.ndarray, list[dict]]:
    """Mean relative load error (and its standard error) of each layout over loads x seeds."""
    tasks = [
        IdentifyTask(
            problem,
            tuple(tuple(float(v) for v in r) for r in rects),
            load,
            settings.noise_fraction,
            seed,
            settings.truth_nodes,
            None,
            settings.t_end,
            i,
        )
        for load in settings.loads  # grouped by load: a process simulates each truth once
        for i, rects in enumerate(layouts_rects)
        for seed in settings.seeds
    ]
    recs = run_tasks(tasks, mapper)
    errs = [[r["load_error"] for r in recs if r["tag"] == i] for i in range(len(layouts_rects))]
    scores = np.array([np.mean(e) for e in errs])
    spread = np.array([np.std(e, ddof=1) / np.sqrt(len(e)) if len(e) > 1 else np.nan for e in errs])
    return scores, spread, recs


def rerank(result, settings: MonteCarloSettings | None = None, mapper: Callable | None = None) -> Reranked:
    """Score the short list of a :class:`~wingopt.design.engine.DesignResult` through the estimator."""
    s = settings or MonteCarloSettings()
    lays = shortlist(result, s.shortlist)
    crit = result.risk if result.settings.criterion == "risk" else result.linear
    pred = np.array([crit.value(lay) for lay in lays])
    rects = [result.candidates.rects[lay] for lay in lays]
    log.info("Monte Carlo: %d layouts x %d loads x %d seeds", len(lays), len(s.loads), len(s.seeds))
    scores, spread, recs = monte_carlo_scores(result.problem, rects, s, mapper)
    return Reranked(lays, pred, scores, spread, int(np.argmin(scores)), recs)


def adopt(result, reranked: Reranked):
    """A copy of a ``risk`` design with the Monte Carlo winner as its layout (predictions redone)."""
    import dataclasses

    from wingopt.design.criteria import reduced_value as _reduced_value

    if result.settings.criterion != "risk":
        raise InputError(f"criterion = {result.settings.criterion!r}: Monte Carlo re-ranking adopts risk designs only")
    new = np.asarray(reranked.layouts[reranked.best])
    risk, linear = result.risk, result.linear
    pred = dict(result.predictions)
    pred["risk_relative_load_error"] = float(risk.value(new))
    pred["risk_per_nominal"] = [float(v) for v in risk.per_nominal(risk.layout_sum(new)[None], new.size)[0]]
    pred["a_relative_posterior_std"] = float(linear.value(new))
    pred["montecarlo_relative_load_error"] = float(reranked.scores[reranked.best])
    rel = dict(result.relaxation)
    red = _reduced_value(linear, *linear.reduced(result.settings.rank)[:3], new)
    rel.update(
        chosen_reduced=red, gap=red - rel["bound"], relative_gap=(red - rel["bound"]) / abs(red) if red else None
    )
    base = dict(result.baselines)
    base["montecarlo"] = reranked.summary()
    return dataclasses.replace(
        result,
        layout=new,
        value=float(risk.value(new)),
        predictions=pred,
        relaxation=rel,
        baselines=base,
        risk_layout=new,
    )
