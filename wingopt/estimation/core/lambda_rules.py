"""One registry of the rules that choose a Tikhonov weight lambda, each under its own name.

The MHE and the JEKF choose lambda differently (a lambda path on the first window vs whole-record
filter runs), and two rules of the studies look at the true load. Before this registry two
different rules were both called "discrepancy"; here every rule has one distinct name, says which
estimator runs it and whether it uses the truth. The old per-estimator names stay accepted as
aliases (``resolve("discrepancy", "jekf")`` is ``"late-innovation-lr"``).

==========================  =========  ===========  =================================================
name                        estimator  uses truth   rule
==========================  =========  ===========  =================================================
``knee`` (MHE default)      mhe        no           misfit knee / 3 (:func:`~.regularization.knee_lambda`)
``morozov``                 mhe        no           chi2 <= tau (n - dof) (:func:`~.regularization.discrepancy_lambda`)
``gcv``                     mhe        no           generalized cross-validation on the lambda path
``late-innovation-lr``      jekf       no           likelihood-ratio test on late innovations (tuned JEKF default)
``prediction-evidence``     jekf       no           max. prediction-error log-likelihood of the record
``quasi-optimality``        jekf       no           min. change of the final load between grid values
``seed-nelder-mead``        jekf-seed  **yes**      the seed's Nelder–Mead on the final TRUE load error
``oracle``                  studies    **yes**      best lambda against the truth (studies only)
==========================  =========  ===========  =================================================
"""

from __future__ import annotations

from dataclasses import dataclass

from wingopt.errors import InputError

__all__ = ["LambdaRuleSpec", "RULES", "resolve", "rules_for", "default_rule"]


@dataclass(frozen=True)
class LambdaRuleSpec:
    """One lambda rule: its name, the estimator that runs it, the estimator's own key for it."""

    name: str
    estimator: str
    internal: str
    uses_truth: bool
    summary: str


RULES: dict[str, LambdaRuleSpec] = {
    r.name: r
    for r in (
        LambdaRuleSpec("knee", "mhe", "robust", False, "misfit knee of the first window's lambda path, / 3"),
        LambdaRuleSpec("morozov", "mhe", "discrepancy", False, "largest lambda with chi2 <= tau (n - dof)"),
        LambdaRuleSpec("gcv", "mhe", "gcv", False, "minimum of n chi2 / (n - dof)^2 on the lambda path"),
        LambdaRuleSpec(
            "late-innovation-lr", "jekf", "discrepancy", False, "largest lambda whose late innovations pass an LR test"
        ),
        LambdaRuleSpec("prediction-evidence", "jekf", "evidence", False, "max. prediction-error log-likelihood"),
        LambdaRuleSpec("quasi-optimality", "jekf", "quasi-optimality", False, "min. change of the final load"),
        LambdaRuleSpec("seed-nelder-mead", "jekf-seed", "seed", True, "the seed's Nelder–Mead on the true load error"),
        LambdaRuleSpec("oracle", "studies", "oracle", True, "best lambda against the truth (studies only)"),
    )
}

_ALIASES = {
    ("mhe", "robust"): "knee",
    ("mhe", "discrepancy"): "morozov",
    ("jekf", "discrepancy"): "late-innovation-lr",
    ("jekf", "evidence"): "prediction-evidence",
}

_DEFAULTS = {"mhe": "knee", "jekf": "late-innovation-lr", "jekf-seed": "seed-nelder-mead"}


def default_rule(estimator: str) -> LambdaRuleSpec:
    """The rule ``estimator`` uses when none is named."""
    return RULES[_DEFAULTS[estimator]]


def rules_for(estimator: str) -> list[str]:
    """Names of the data-only rules (and aliases) an estimator accepts."""
    names = [r.name for r in RULES.values() if r.estimator == estimator and not r.uses_truth]
    return names + [alias for (est, alias) in _ALIASES if est == estimator]


def resolve(name: str | None, estimator: str) -> LambdaRuleSpec:
    """The rule called ``name`` (or an estimator's alias of it); ``None``: the estimator's default.

    Raises :class:`InputError` naming the rules ``estimator`` accepts when ``name`` is not one.
    """
    if estimator not in _DEFAULTS:
        raise InputError(f"estimator = {estimator!r}: expected one of {', '.join(_DEFAULTS)}")
    if name is None:
        return default_rule(estimator)
    key = str(name).strip().lower()
    key = _ALIASES.get((estimator, key), key)
    spec = RULES.get(key)
    if spec is None or spec.estimator != estimator:
        accepted = rules_for(estimator) or [default_rule(estimator).name]
        raise InputError(f"lambda rule = {name!r}: the {estimator} estimator accepts {', '.join(accepted)}")
    return spec
