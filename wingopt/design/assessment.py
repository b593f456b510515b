"""What a design reports about the layout it found: the relaxation's bound and gap, and the baselines.

The search (:func:`~wingopt.design.engine.design_sensors`: relaxation, rounding, greedy, swaps)
returns a :class:`~wingopt.design.search.Search`; the reports here judge its layout against the convex bound and against
the other starts and the problem's own layout, adding a warning where the judgement is poor.
"""

from __future__ import annotations

import numpy as np

from wingopt.design.criteria import LinearCriterion
from wingopt.design.criteria import reduced_value as _reduced_value
from wingopt.design.search import Search

__all__ = ["relaxation_report", "baseline_report"]


def relaxation_report(kind: str, linear: LinearCriterion, found: Search, warnings: list[str]) -> dict:
    """The relaxation's bound against the chosen layout's reduced value (a warning when loose)."""
    rel = found.relaxation
    info_r, weight_r, const_r, _ = found.reduced
    red = _reduced_value(linear, info_r, weight_r, const_r, found.best)
    relaxation = {
        "criterion": kind,
        "bound": rel.bound,
        "chosen_reduced": red,
        "gap": red - rel.bound,
        "relative_gap": (red - rel.bound) / abs(red) if red else None,
        "rounded_value": linear.value(found.rounded),
        "solver": rel.solver,
        "status": rel.status,
        "rank": rel.rank,
        "dropped_information": rel.dropped,
        "weights_above_half": int(np.sum(rel.weights > 0.5)),
        "weights_above_1e-3": int(np.sum(rel.weights > 1e-3)),
    }
    if relaxation["relative_gap"] is not None and relaxation["relative_gap"] > 0.2:
        warnings.append(
            f"relaxation is loose: the chosen layout is {100 * relaxation['relative_gap']:.0f} % above the bound "
            f"({relaxation['weights_above_1e-3']} candidates share the relaxed weight)"
        )
    return relaxation


def baseline_report(crit, found: Search, default_idx, count: int, warnings: list[str]) -> dict:
    """The starts' values and the problem's own layout's under the searched criterion ``crit`` (a
    warning when the problem's layout beats the design)."""
    baselines = {
        "greedy": {"layout": found.greedy.tolist(), "value": float(crit.value(found.greedy))},
        "relaxation_rounded": {"layout": found.rounded.tolist(), "value": float(crit.value(found.rounded))},
        "improved_from": found.came_from,
    }
    if default_idx is not None and default_idx.size == count:
        baselines["problem_layout"] = {"layout": default_idx.tolist(), "value": float(crit.value(default_idx))}
        if crit.value(default_idx) < found.value:
            warnings.append("the problem's own layout scores better than the design (local optimum of the swaps)")
    return baselines
