"""The search for a design's layout: relaxation, rounding, greedy starts, swaps.

The convex relaxation of the linear criterion gives a bound and, rounded, a start; greedy gives
others (on the risk too, for a few sensors); swaps improve every start under the design's criterion
and the best layout wins (:mod:`wingopt.design.selection` holds the steps).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wingopt.design.criteria import LinearCriterion
from wingopt.design.risk import BayesRisk
from wingopt.design.selection import greedy, relax, round_weights, swap_improve

__all__ = ["Search", "search_layout"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Search:
    """The layout a design's search found and where it came from."""

    best: np.ndarray
    value: float
    came_from: str
    rounded: np.ndarray  # the relaxation's weights rounded to a layout
    greedy: np.ndarray  # the greedy layout of the linear criterion
    relaxation: object  # the relaxation's result (bound, weights, solver, status, rank, dropped)
    reduced: tuple  # the linear criterion reduced for the SDP (info, weight, const, ...)


def search_layout(
    linear: LinearCriterion,
    risk: BayesRisk | None,
    count: int,
    overlap: np.ndarray | None,
    stack,
    rank: int,
    swap_passes: int,
    say: Callable[[str, float], None],
    t0: float,
    timings: dict[str, float],
) -> Search:
    """Relax, round, start greedy, and improve every start by swaps: the best layout of ``count``.

    ``risk`` (the design's criterion when given, else ``linear``) is what the swaps minimise; the
    relaxation (of ``linear``, to ``rank`` directions) and greedy give the starts. ``overlap``: the
    pairs that may not be chosen together (``None``: any). ``say(stage, fraction)`` reports progress
    and ``timings`` gets each stage's seconds (logged against ``t0``)."""
    t2 = time.perf_counter()
    say("relaxation", 0.0)
    reduced = linear.reduced(rank)
    with stack.spilled():  # the solver's copy of the SDP is large: the information waits on disk
        rel = relax(linear, count, rank, reduced=reduced)
    timings["relaxation"] = time.perf_counter() - t2
    log.info("relaxation done at %.1f s", time.perf_counter() - t0)
    rounded = round_weights(rel.weights, count, overlap)
    t3 = time.perf_counter()
    greedy_risk = risk is not None and count <= 8 and swap_passes > 0
    share = 0.5 if greedy_risk else 1.0
    g_layout, _ = greedy(linear, count, overlap, tick=lambda f: say("greedy", share * f))
    starts = {"relaxation": rounded, "greedy": g_layout}
    if greedy_risk:
        # greedy on the risk itself is a third start (costly for many sensors: K batched passes)
        starts["greedy-risk"] = greedy(risk, count, overlap, tick=lambda f: say("greedy", 0.5 + 0.5 * f))[0]
    timings["greedy"] = time.perf_counter() - t3
    log.info("greedy done at %.1f s", time.perf_counter() - t0)
    t4 = time.perf_counter()
    search = risk if risk is not None else linear
    best, best_val, best_from = None, np.inf, None
    for n, (name, start) in enumerate(starts.items()):
        # passes done -> a fraction of this start's swaps (how many passes it takes is not known)
        lay, path = swap_improve(
            search,
            start,
            overlap,
            max_passes=swap_passes,
            tick=lambda p, n=n: say("swaps", (n + p / (np.floor(p) + 2)) / len(starts)),
        )
        if path[-1] < best_val:
            best, best_val, best_from = lay, path[-1], name
    timings["swaps"] = time.perf_counter() - t4
    log.info("swaps done at %.1f s", time.perf_counter() - t0)
    return Search(best, best_val, best_from, rounded, g_layout, rel, reduced)
