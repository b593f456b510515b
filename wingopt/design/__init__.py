"""Optimal stretch-sensor layouts for membrane load identification (spec §9, issue 13).

``design_sensors(problem, K)`` chooses ``K`` rectangles from a candidate grid: information of each
candidate linearised along expected responses (:mod:`~wingopt.design.information`), Bayesian
criteria (:mod:`~wingopt.design.criteria`: A, lift, D; :mod:`~wingopt.design.risk`: the
estimator's expected bias + noise), convex relaxation with a bound, rounding, swaps and greedy
(:mod:`~wingopt.design.selection`); the candidates' information is held packed
(:mod:`~wingopt.design.stack`). :mod:`~wingopt.design.montecarlo` runs the real estimator on
layouts as a map over independent tasks. An engine: it reads no problem file, writes no file and
draws nothing (:mod:`wingopt.workflows.design` does, through :mod:`wingopt.results` and
:mod:`wingopt.plots`). See ``docs/sensor_design.md``.
"""

from wingopt.design.candidates import CandidateSet, candidate_grid, parse_candidates
from wingopt.design.criteria import LinearCriterion
from wingopt.design.engine import CRITERIA, DesignResult, DesignSettings, design_sensors, predicted_error_field
from wingopt.design.information import InformationSettings, ModalSensitivity
from wingopt.design.risk import BayesRisk

__all__ = [
    "design_sensors",
    "DesignSettings",
    "DesignResult",
    "predicted_error_field",
    "CRITERIA",
    "InformationSettings",
    "ModalSensitivity",
    "CandidateSet",
    "candidate_grid",
    "parse_candidates",
    "LinearCriterion",
    "BayesRisk",
]
