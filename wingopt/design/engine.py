"""``design_sensors``: where to put K stretch sensors (spec §9), the engine behind ``wingopt design-sensors``.

Pipeline: candidates (:mod:`~wingopt.design.candidates`) -> information of each candidate along a
family of nominal responses (:mod:`~wingopt.design.information`; robust design over the family)
-> criterion -> selection (:mod:`~wingopt.design.selection`):

* linear criteria ``a`` / ``lift`` / ``d`` (prior ``gp`` or ``tikhonov``): convex relaxation (the
  bound), rounding, swaps; greedy as a baseline;
* ``risk`` (default, :mod:`~wingopt.design.risk`): the bias-aware expected error of the
  estimator; started from the relaxed A-design and from greedy, improved by swaps. It has no convex
  bound; the A-relaxation's bound and gap are reported for the chosen layout.

:func:`predicted_error_field` is the field the layout figure shows. Nothing here writes files or
draws: :mod:`wingopt.workflows.design` hands the result to :mod:`wingopt.results` and
:mod:`wingopt.plots`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from wingopt import resources
from wingopt.design.assessment import baseline_report, relaxation_report
from wingopt.design.candidates import CandidateSet, parse_candidates, with_problem_sensors
from wingopt.design.criteria import LINEAR_CRITERIA, LinearCriterion, state_prior_std
from wingopt.design.information import InformationSettings, ModalSensitivity
from wingopt.design.priors import PRIORS, gp_prior, smooth_loads, tikhonov_prior
from wingopt.design.risk import BayesRisk
from wingopt.design.search import Search, search_layout
from wingopt.design.selection import overlap_matrix
from wingopt.design.stack import information_stack
from wingopt.errors import InputError
from wingopt.estimation.declaration import declaration_of
from wingopt.membrane import MembraneModel
from wingopt.status import RunStatus, from_solver_statuses

__all__ = ["CRITERIA", "STAGES", "DesignSettings", "DesignResult", "design_sensors", "predicted_error_field"]
__all__ += ["check_sensor_count"]

log = logging.getLogger(__name__)

CRITERIA = ("risk", *LINEAR_CRITERIA)

STAGES = ("model", "information", "criteria", "relaxation", "greedy", "swaps")
"""The stages a design reports to its ``progress`` callable, in order."""

DEFAULT_LENGTH = 0.2
"""Default length scale of the load prior and of the nominal loads, as a fraction of the chord."""

MAX_COUNT, MAX_NOMINAL = 1000, 1000
"""Most sensors one design may place (as many as a problem file may list), and nominal loads."""


@dataclass(frozen=True)
class DesignSettings:
    """Settings of a design (defaults: the protocol: 1 % noise, 1 s at the problem's rate).

    Parameters
    ----------
    criterion : {"risk", "a", "lift", "d"}
    prior : {"gp", "tikhonov"}
        Load prior of the linear criteria (``risk`` uses the estimator's Tikhonov term and its rule).
    length_scale : float or None
        GP length scale (m) of the prior and of the nominal loads; default 0.2 of the chord.
    nominal_count, nominal_seed : int
        The family of nominal loads (smooth GP draws) the information is linearised along; the
        criteria are averaged (``aggregate="mean"``) or worst-cased (``"max"``) over it. Default
        count: 12 for ``risk`` (its ranking of layouts is stable from about 12 draws, measured),
        4 for the linear criteria.
    allow_overlap : bool
        Whether chosen rectangles may overlap (default no: one membrane, one sensor per spot).
    rank : int
        Directions kept in the SDP relaxation.
    swap_passes : int
        Most passes of the swap search (each pass tries every position once).
    """

    criterion: str = "risk"
    prior: str = "gp"
    length_scale: float | None = None
    nominal_count: int | None = None
    nominal_seed: int = 7
    aggregate: str = "mean"
    allow_overlap: bool = False
    rank: int = 12
    swap_passes: int = 20
    information: InformationSettings = field(default_factory=InformationSettings)

    def __post_init__(self):
        if self.criterion not in CRITERIA:
            raise InputError(f"criterion = {self.criterion!r}: expected one of {', '.join(CRITERIA)}")
        if self.prior not in PRIORS:
            raise InputError(f"prior = {self.prior!r}: expected one of {', '.join(PRIORS)}")
        if self.aggregate not in ("mean", "max"):
            raise InputError(f"aggregate = {self.aggregate!r}: expected 'mean' or 'max'")
        if self.nominal_count is not None and not (isinstance(self.nominal_count, int) and self.nominal_count >= 1):
            raise InputError(f"nominal_count = {self.nominal_count!r}: expected a positive integer")
        if self.nominal_count is not None and self.nominal_count > MAX_NOMINAL:
            raise InputError(
                f"nominal_count = {self.nominal_count}: more than the limit of {MAX_NOMINAL} nominal loads"
            )
        if self.length_scale is not None and not self.length_scale > 0:
            raise InputError(f"length_scale = {self.length_scale!r}: expected a positive length (m)")


@dataclass(eq=False)
class DesignResult:
    """A designed layout with its predictions, the relaxation bound and gap, baselines and warnings."""

    problem: object
    settings: DesignSettings
    candidates: CandidateSet
    layout: np.ndarray  # candidate indices
    value: float  # the chosen criterion (lower is better)
    predictions: dict
    relaxation: dict
    baselines: dict
    timings: dict
    warnings: list[str]
    risk: BayesRisk | None = None
    sensitivity: ModalSensitivity | None = None
    linear: LinearCriterion | None = None
    risk_layout: np.ndarray | None = None  # the layout's indices in ``risk`` (a subset for linear criteria)

    @property
    def rects(self) -> np.ndarray:
        return self.candidates.rects[self.layout]

    @property
    def count(self) -> int:
        return int(self.layout.size)

    @property
    def nominal_loads(self):
        """The nominal pressures the design was linearised along (callables)."""
        return nominal_loads(self.problem, self.settings)

    @property
    def status(self) -> RunStatus:
        """``converged``, or ``not_converged`` when the relaxation's solver came back inaccurate (its bound is
        then approximate): :class:`~wingopt.status.RunStatus`."""
        return from_solver_statuses([str(self.relaxation.get("status", "optimal")).lower()])

    def __repr__(self) -> str:  # the candidates and the sensitivities would print 10 000s of characters
        return (
            f"DesignResult(count={self.count}, criterion={self.settings.criterion!r}, value={self.value:.4g}, "
            f"candidates={len(self.candidates)}, status='{self.status}', warnings={len(self.warnings)})"
        )

    def summary(self) -> dict:
        return {
            "problem": getattr(self.problem, "name", "membrane"),
            "status": str(self.status),
            "count": self.count,
            "criterion": self.settings.criterion,
            "prior": self.settings.prior,
            "aggregate": self.settings.aggregate,
            "candidates": len(self.candidates),
            "layout": [{"name": f"S{i + 1}", "rect": [float(v) for v in r]} for i, r in enumerate(self.rects)],
            "value": self.value,
            "predictions": self.predictions,
            "relaxation": self.relaxation,
            "baselines": self.baselines,
            "timings_s": self.timings,
            "warnings": list(self.warnings),
        }


def nominal_loads(problem, s: DesignSettings):
    """The smooth GP draws of a design's nominal family."""
    count = s.nominal_count or (12 if s.criterion == "risk" else 4)
    return smooth_loads(problem.width, problem.height, count, s.nominal_seed, _length(problem, s))


def _length(problem, s: DesignSettings) -> float:
    return DEFAULT_LENGTH * problem.width if s.length_scale is None else s.length_scale


def check_sensor_count(count) -> None:
    """Refuse a sensor count that is not a positive integer within :data:`MAX_COUNT` (the one check)."""
    if isinstance(count, bool) or not (isinstance(count, (int, np.integer)) and count >= 1):
        raise InputError(f"count = {count!r}: expected a positive number of sensors")
    if count > MAX_COUNT:
        raise InputError(f"count = {count}: more than the limit of {MAX_COUNT} sensors to design")


def _checked_settings(problem, count, candidates, settings, overrides: dict) -> DesignSettings:
    """The design's settings (``overrides`` applied) once its inputs are known good."""
    if getattr(problem, "kind", None) != "membrane":
        raise InputError(
            f"problem: sensor design needs a membrane problem, got kind {getattr(problem, 'kind', None)!r}"
        )
    if settings is not None and not isinstance(settings, DesignSettings):
        raise InputError(f"settings = {settings!r}: expected a DesignSettings or None")
    s = settings or DesignSettings()
    if overrides:
        import dataclasses

        for key in sorted(set(overrides) - {f.name for f in dataclasses.fields(DesignSettings)}):
            raise InputError(f"{key}: not a DesignSettings field")
        s = dataclasses.replace(s, **overrides)
    check_sensor_count(count)
    if candidates is not None and not isinstance(candidates, (str, CandidateSet)):
        raise InputError(f"candidates = {candidates!r}: expected a CandidateSet, a --candidates SPEC string or None")
    return s


def design_sensors(
    problem,
    count: int,
    candidates: CandidateSet | str | None = None,
    settings: DesignSettings | None = None,
    progress=None,
    **overrides,
) -> DesignResult:
    """Choose ``count`` sensor rectangles for a membrane ``problem``.

    Parameters
    ----------
    problem : MembraneProblem
    count : int
        Number of sensors ``K``.
    candidates : CandidateSet or str, optional
        A candidate set or a ``--candidates`` SPEC (default: the problem's sensor sizes on the
        half-element lattice).
    settings : DesignSettings, optional
    progress : callable, optional
        ``progress(stage, fraction)`` as the work goes: ``stage`` one of :data:`STAGES`, ``fraction``
        of it done (swaps: an estimate, their passes are not known ahead). The command's stage lines.
    **overrides
        Fields of :class:`DesignSettings` (e.g. ``criterion="a"``).
    """
    s = _checked_settings(problem, count, candidates, settings, overrides)
    resources.check(resources.estimate_modes(problem.nodes, "membrane", knob="mesh"))
    t0 = time.perf_counter()
    log.info("design: %d sensors, criterion %s", count, s.criterion)
    if candidates is None or isinstance(candidates, str):
        candidates = parse_candidates(candidates, problem, s.information.sub)
    cands, default_idx = with_problem_sensors(problem, candidates)
    if count > len(cands):
        raise InputError(f"count = {count}: more than the {len(cands)} candidates")
    nominal = s.nominal_count or (12 if s.criterion == "risk" else 4)
    resources.check(resources.estimate_design(problem.nodes, len(cands), nominal, count))
    say = progress or (lambda stage, fraction: None)
    timings: dict[str, float] = {}
    info = _information(problem, s, cands, say, t0, timings)
    crit = _criteria(problem, s, count, info, say, t0, timings)
    overlap = None if s.allow_overlap else overlap_matrix(cands.rects)
    found = search_layout(crit.linear, crit.risk, count, overlap, info.stack, s.rank, s.swap_passes, say, t0, timings)
    risk, risk_index = _risk_of(crit, info, s, default_idx, found)
    warnings: list[str] = []
    relaxation = relaxation_report(crit.kind, crit.linear, found, warnings)
    baselines = baseline_report(
        crit.risk if crit.risk is not None else crit.linear, found, default_idx, count, warnings
    )
    pred = predictions(s, count, crit, info, risk, risk_index, found.best, warnings)
    timings["total"] = time.perf_counter() - t0
    return DesignResult(
        problem,
        s,
        cands,
        np.asarray(found.best),
        float(found.value),
        pred,
        relaxation,
        baselines,
        timings,
        warnings,
        risk,
        info.sens,
        crit.linear,
        risk_index,
    )


@dataclass(frozen=True)
class _Information:
    """The packed information of every candidate along the nominal family, and what built it."""

    model: MembraneModel
    sens: ModalSensitivity
    q0: np.ndarray
    loads: list
    stack: object


def _information(problem, s: DesignSettings, cands: CandidateSet, say, t0: float, timings: dict) -> _Information:
    """The information of every candidate, packed (:mod:`wingopt.design.stack`): the design's memory."""
    say("model", 0.0)
    model = MembraneModel.from_problem(problem.with_sensors(()))
    sens = ModalSensitivity.from_model(model, s.information)
    chat = sens.modal_matrices(cands.rects)
    q0 = sens.initial_state()
    loads = nominal_loads(problem, s)
    scale = np.concatenate([state_prior_std(sens, q0), np.ones(sens.m)])
    modal = [sens.modal_load(model.project(P)) for P in loads]
    stack = information_stack(sens, chat, modal, q0, scale, progress=lambda f: say("information", f))
    timings["information"] = time.perf_counter() - t0
    log.info(
        "information of %d candidates x %d nominal loads in %.1f s (%.0f MB)",
        len(cands),
        len(loads),
        timings["information"],
        stack.nbytes / 2**20,
    )
    return _Information(model, sens, q0, loads, stack)


@dataclass(frozen=True)
class _Criteria:
    """The design's criteria: the risk (when it is the criterion), the linear one and its prior."""

    kind: str
    risk: BayesRisk | None
    linear: LinearCriterion
    prior: object


def _criteria(problem, s: DesignSettings, count: int, info: _Information, say, t0: float, timings: dict) -> _Criteria:
    """Build the risk (over all candidates only when it is the criterion) and the linear criterion."""
    t1 = time.perf_counter()
    say("criteria", 0.0)
    sens, stack, loads, q0 = info.sens, info.stack, info.loads, info.q0
    risk = BayesRisk.build(sens, stack, loads, q0, s.aggregate) if s.criterion == "risk" else None
    if s.prior == "gp":
        prior = gp_prior(info.model, _length(problem, s), abs(declaration_of(problem).initial_load))
    else:
        mean_sum = stack.mean()[None] * count
        r_ = risk or BayesRisk.build(sens, stack.take([0]), loads, q0)
        prior = tikhonov_prior(info.model, float(np.mean(r_.rule_lambdas(mean_sum, count))))
    kind = "a" if s.criterion == "risk" else s.criterion
    linear = LinearCriterion.build(kind, sens, stack, prior, q0, s.aggregate)
    timings["criteria"] = time.perf_counter() - t1
    log.info("criteria done at %.1f s", time.perf_counter() - t0)
    return _Criteria(kind, risk, linear, prior)


def _risk_of(crit: _Criteria, info: _Information, s: DesignSettings, default_idx, found: Search):
    """The risk and the chosen layout's indices in it: for a linear criterion, the risk on the
    layouts reported only (the chosen one, the starts, the problem's own)."""
    best = found.best
    if crit.risk is not None:
        return crit.risk, np.asarray(best)
    keep = [best, found.rounded, found.greedy] + ([default_idx] if default_idx is not None else [])
    sub = np.unique(np.concatenate(keep))
    risk = BayesRisk.build(info.sens, info.stack.take(sub), info.loads, info.q0, s.aggregate)
    where = {int(c): k for k, c in enumerate(sub)}
    return risk, np.array([where[int(c)] for c in best])


def predictions(s, count, crit: _Criteria, info: _Information, risk, risk_index, best, warnings: list) -> dict:
    """The chosen layout's predicted errors: the risk, its value per nominal load, the A criterion's
    relative posterior std (and the lift's when it is the criterion); a warning when the risk is poor."""
    sens, stack, q0, linear, kind = info.sens, info.stack, info.q0, crit.linear, crit.kind
    pred = {
        "risk_relative_load_error": float(risk.value(risk_index)),
        "risk_per_nominal": [float(v) for v in risk.per_nominal(risk.layout_sum(risk_index)[None], count)[0]],
        "a_relative_posterior_std": float(
            linear.value(best) if kind == "a" else LinearCriterion.build("a", sens, stack, crit.prior, q0).value(best)
        ),
        "nominal_loads": [P.description for P in info.loads],
    }
    if kind == "lift":
        pred["lift_relative_posterior_std"] = float(linear.value(best))
    if s.criterion == "risk" and pred["risk_relative_load_error"] > 0.5:
        warnings.append(
            f"predicted mean load error {pred['risk_relative_load_error']:.2f}: {count} sensors resolve the "
            "nominal loads poorly (more sensors, or a load space that fits the edges)"
        )
    return pred


def predicted_error_field(result: DesignResult, nx: int = 57, ny: int = 29):
    """``(X, Y, E)``: the relative RMS pointwise error of the design's linearised estimates.

    ``E`` is the RMS over the nominal loads of the linearised, noise-free estimator's error
    ``|P - f^|`` (:meth:`~wingopt.design.risk.BayesRisk.load_coefficients`), relative to the RMS
    pressure: where the layout leaves the load unresolved.
    """
    prob, sens, loads = result.problem, result.sensitivity, result.nominal_loads
    coefs = result.risk.load_coefficients(result.risk_layout)
    X, Y = np.meshgrid(np.linspace(0, prob.width, nx), np.linspace(0, prob.height, ny))
    err2 = np.zeros_like(X)
    ref2 = 0.0
    for P, c in zip(loads, coefs):
        est = sens.model.space.evaluate(c, X.ravel(), Y.ravel()).reshape(X.shape)
        truth = P(X, Y)
        err2 += (truth - est) ** 2
        ref2 += float(np.mean(truth**2))
    return X, Y, np.sqrt(err2 / len(loads)) / np.sqrt(ref2 / len(loads))
