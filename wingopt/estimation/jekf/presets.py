"""The two JEKF baselines as presets: the seed-faithful filter and the tuned one.

:func:`identify` runs the JEKF the way the command line and the comparison studies do: the
``"seed"`` preset (:meth:`JEKFSettings.seed`, ``lambda`` by the seed's Nelder–Mead on the truth
when a simulated truth is at hand) or the ``"tuned"`` preset (:meth:`JEKFSettings.tuned`,
``lambda`` by a data-only rule, :mod:`wingopt.estimation.jekf.tuning`).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from typing import Any

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.core.result import IdentificationResult
from wingopt.estimation.jekf.filter import JointEKF
from wingopt.estimation.jekf.seed_lambda import LambdaSearch, _as_lambda, seed_lambda
from wingopt.estimation.jekf.settings import JEKFSettings
from wingopt.estimation.jekf.tuning import tuned_identify
from wingopt.measurements.series import Measurements
from wingopt.membrane.model import MembraneModel

__all__ = ["jekf_identify", "VARIANTS", "identify", "cached_seed_lambda", "noise_free"]

log = logging.getLogger(__name__)

VARIANTS = ("seed", "tuned")


_SEED_CACHE: dict[Any, LambdaSearch] = {}


def noise_free(case):
    """The noise-free twin of a :class:`~wingopt.membrane.TruthRecord` (same truth)."""
    meas = Measurements(
        t=case.trajectory.t,
        values=case.trajectory.outputs,
        sensor_names=case.measurements.sensor_names,
        noise_std=np.zeros(case.trajectory.outputs.shape[1]),
        source=f"noise-free {case.load.name}",
        simulated=True,
    )
    return dataclasses.replace(case, measurements=meas, noise_fraction=0.0, seed=None)


def cached_seed_lambda(model: MembraneModel, case, settings: JEKFSettings | None = None, **kwargs: Any) -> LambdaSearch:
    """:func:`seed_lambda` on the noise-free twin of ``case``, cached per (problem, settings, truth)."""
    settings = (JEKFSettings.seed() if settings is None else settings).replace(regularization=1.0)
    key = (model.problem, settings, hash(case.trajectory.outputs.tobytes()), tuple(sorted(kwargs.items())))
    if key not in _SEED_CACHE:
        _SEED_CACHE[key] = seed_lambda(model, noise_free(case), settings, **kwargs)
    return _SEED_CACHE[key]


def identify(
    model: MembraneModel,
    measurements: Measurements,
    variant: str = "tuned",
    truth=None,
    initial_load: float | None = None,
    regularization: float | None = None,
    rule: str = "discrepancy",
    modes: int | None = None,
    **kwargs: Any,
) -> IdentificationResult:
    """The JEKF as the command line and the comparison studies run it.

    Parameters
    ----------
    variant : {"seed", "tuned"}
        ``"seed"``: the seed-faithful filter (``R = 1e-4``, uniform ``initial_load`` prior, the
        bubble); ``lambda`` from :func:`seed_lambda` on the noise-free twin of ``truth`` (USES THE
        TRUTH, as the seed did); without a truth ``regularization`` must be given.
        ``"tuned"``: zero initial load, ``R`` from the data, ``lambda`` by the data-only ``rule``.
    truth : TruthRecord, optional
        The simulated case (only the seed variant uses it, and only to tune ``lambda``).
    initial_load : float, optional
        Signed prior pressure (Pa): the seed's uniform prior mean, and for both variants the sign
        prior when the problem states no initial deflection. Default: the problem's.
    regularization : float, optional
        Fixed ``lambda`` (skips the tuning).
    modes : int, optional
        Keep only the lowest ``modes`` membrane modes (:attr:`JEKFSettings.modes`; faster,
        approximate); default: all (exact).
    kwargs :
        Passed to :func:`select_lambda` (tuned) or :func:`seed_lambda` (seed).

    Returns
    -------
    IdentificationResult
        The run at the chosen lambda; ``info`` says where lambda came from (``lambda_source``).
    """
    if variant not in VARIANTS:
        raise InputError(f"variant = {variant!r}: expected one of {', '.join(VARIANTS)}")
    if initial_load is not None and not (math.isfinite(initial_load) and initial_load != 0):
        raise InputError(f"initial_load = {initial_load!r}: expected a non-zero pressure (Pa)")
    if variant == "seed":
        settings = JEKFSettings.seed(initial_load=initial_load).replace(modes=modes)
        t0 = time.perf_counter()
        if regularization is not None:
            lam, source, search = _as_lambda("regularization", regularization), "given", None
        elif truth is not None:
            search = cached_seed_lambda(model, truth, settings, **kwargs)
            lam, source = search.regularization, "seed method: Nelder-Mead on the noise-free truth (uses the truth)"
        else:
            raise InputError(
                "jekf-seed: the seed's filter tunes its lambda on the simulated truth; a measured record has none: "
                "give --lambda, or use --method jekf-tuned (lambda from the data)"
            )
        tune_s = time.perf_counter() - t0
        res = JointEKF(model, settings.replace(regularization=lam)).run(measurements)
        res.info.update(variant="seed", lambda_source=source, tuning_wall_s=tune_s)
        if search is not None:
            res.info["seed_search"] = {
                "lambda": search.regularization,
                "noise_free_error": search.error,
                "evaluations": search.evaluations,
                "history": [list(h) for h in search.history],
                "method": search.method,
            }
        return res
    settings = JEKFSettings.tuned(sign_prior=initial_load).replace(modes=modes)
    if regularization is not None:
        res = JointEKF(model, settings.replace(regularization=_as_lambda("regularization", regularization))).run(
            measurements
        )
        res.info.update(variant="tuned", lambda_source="given")
        return res
    res = tuned_identify(model, measurements, rule=rule, settings=settings, **kwargs)
    res.info.update(variant="tuned", lambda_source=f"data-only rule: {rule}")
    return res


def jekf_identify(
    model: MembraneModel,
    measurements: Measurements,
    settings: JEKFSettings | None = None,
    **changes: Any,
) -> IdentificationResult:
    """One-shot JEKF: ``JointEKF(model, settings.replace(**changes)).run(measurements)``.

    Parameters
    ----------
    model : MembraneModel
        Estimator model.
    measurements : Measurements
        The record (NaN = missing).
    settings : JEKFSettings, optional
        Default :meth:`JEKFSettings.seed`; keyword ``changes`` override its fields, e.g.
        ``jekf_identify(model, meas, regularization=1e-8)``.

    Returns
    -------
    IdentificationResult
        Posterior histories at every sample (see :meth:`JointEKF.run`).
    """
    settings = JEKFSettings.seed() if settings is None else settings
    if changes:
        try:
            settings = settings.replace(**changes)
        except TypeError as exc:
            raise InputError(f"jekf_identify: {exc}") from exc
    return JointEKF(model, settings).run(measurements)
