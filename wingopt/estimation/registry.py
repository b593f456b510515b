"""One registry of load estimators: which (estimator, membrane) pairs exist and what each one uses.

Every estimator of the package is one row, :class:`EstimatorSpec`, keyed by its method, the
membrane physics it assumes and whether it streams. A row names the estimator's settings
dataclass, whose fields declare the options of
:class:`~wingopt.estimation.options.IdentifyOptions` it takes (so the options are derived, not
listed here); :func:`check_options`
refuses, in one line, every option the chosen pair would ignore. No method or model name is
written outside this module: the command line and the workflows ask it.

=============  =======================  ======  =========================================================
method         membrane                 stream  estimator
=============  =======================  ======  =========================================================
``mhe``        linear                   no      moving-horizon Tikhonov (:mod:`.mhe`), adequacy checked
``jekf-seed``  linear                   no      the seed's joint EKF (200 Pa prior, lambda tuned on the truth)
``jekf-tuned`` linear                   no      joint EKF, zero initial load, lambda from the data
``batch``      berger, fvk              no      whole-record fit, prestrains and damping identified (:mod:`.realistic`)
``mhe``        linear                   yes     real-time iteration MHE (:mod:`.streaming`)
``ekf``        berger, fvk              yes     extended Kalman filter on the batch model (:mod:`.streaming.nonlinear`)
``fullfield``  fvk                      no      DIC frames: pressure from the measured shape (:mod:`.fullfield`)
=============  =======================  ======  =========================================================
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

from wingopt.errors import InputError
from wingopt.estimation.core.record_settings import RecordSettings
from wingopt.estimation.fullfield.settings import FullFieldSettings
from wingopt.estimation.jekf.settings import JEKFSettings
from wingopt.estimation.mhe.settings import MHESettings
from wingopt.estimation.options import OPTION_FLAGS, IdentifyOptions, declared_options
from wingopt.estimation.streaming.types import NonlinearStreamSettings, StreamSettings

__all__ = [
    "METHODS",
    "MODELS",
    "EstimatorSpec",
    "REGISTRY",
    "resolve",
    "check_options",
    "METHOD_ALIASES",
    "MODEL_ALIASES",
    "FRAME_METHODS",
]

METHODS = ("auto", "mhe", "batch", "jekf-seed", "jekf-tuned", "ekf", "fullfield")
"""Estimator names (``auto``: :func:`resolve` chooses)."""

FRAME_METHODS = ("fullfield",)
"""Estimators of DIC frames (every other one takes stretch-sensor series: from frames, virtual sensors)."""

MODELS = ("auto", "linear", "berger", "fvk")
"""Membrane physics an estimator assumes (``auto``: :func:`resolve` chooses)."""

METHOD_ALIASES = {"jekf": "jekf-seed", "realistic": "batch"}
MODEL_ALIASES = {"nonlinear": "berger"}
"""Older names still accepted (``--model nonlinear`` was the Berger membrane)."""

_RECORD = frozenset({"noise_std", "initial_load"})
"""Options every record and stream estimator takes beside its settings: the sensors' noise and the sign prior."""


@dataclass(frozen=True)
class EstimatorSpec:
    """One estimator of the registry.

    Attributes
    ----------
    method, model : str
        Its method name and the membrane physics it assumes.
    stream : bool
        One estimate per sample (``push``) rather than a whole record.
    settings : type
        Its settings dataclass; the :class:`IdentifyOptions` it takes are the ones its fields
        declare (:func:`~wingopt.estimation.options.option`).
    summary : str
        One line for ``--help`` and docs.
    extra : frozenset of str
        Options it takes beside its settings (the noise std, the sign prior, the MHE's FvK cross-check).
    requires : tuple of (option, predicate, reason)
        Options used only under a condition on the others (``qp_solver`` only with ``solver="cvxpy"``).
    """

    method: str
    model: str
    stream: bool
    settings: type
    summary: str
    extra: frozenset[str] = _RECORD
    requires: tuple[tuple[str, Callable[[IdentifyOptions], bool], str], ...] = ()

    @property
    def options(self) -> frozenset[str]:
        """The :class:`IdentifyOptions` fields it uses: its settings' declared ones and :attr:`extra`."""
        return declared_options(self.settings) | self.extra

    @property
    def label(self) -> str:
        return f"{self.method} estimator with the {self.model} membrane" + (" (streaming)" if self.stream else "")


def _solver_is(*names: str) -> Callable[[IdentifyOptions], bool]:
    return lambda o: o.solver in names


_MHE_REQUIRES = (
    ("qp_solver", _solver_is("cvxpy"), "it picks the QP solver of --solver cvxpy"),
    (
        "pressure_bounds",
        _solver_is("cvxpy", "ipopt"),
        "the numpy window solver has no bounds (--solver cvxpy or ipopt)",
    ),
    ("load_timescale", lambda o: o.load_model == "varying", "it is the time scale of --load-model random_walk"),
)

REGISTRY: dict[tuple[str, str, bool], EstimatorSpec] = {
    (s.method, s.model, s.stream): s
    for s in (
        EstimatorSpec(
            "mhe",
            "linear",
            False,
            MHESettings,
            "moving-horizon Tikhonov, linear membrane",
            _RECORD | {"model_form"},
            _MHE_REQUIRES,
        ),
        # the seed's filter: R = 1e-4 as the seed set it, so a noise level is not one of its options
        EstimatorSpec("jekf-seed", "linear", False, JEKFSettings, "the seed's joint EKF", frozenset()),
        EstimatorSpec("jekf-tuned", "linear", False, JEKFSettings, "joint EKF, lambda from the data"),
        EstimatorSpec("batch", "berger", False, RecordSettings, "whole-record fit, Berger"),
        EstimatorSpec("batch", "fvk", False, RecordSettings, "whole-record fit, FvK membrane"),
        EstimatorSpec(
            "mhe",
            "linear",
            True,
            StreamSettings,
            "real-time iteration MHE, linear membrane",
            requires=_MHE_REQUIRES[:1],
        ),
        EstimatorSpec("ekf", "berger", True, NonlinearStreamSettings, "extended Kalman filter, Berger membrane"),
        EstimatorSpec("ekf", "fvk", True, NonlinearStreamSettings, "extended Kalman filter, FvK membrane"),
        # DIC frames: the noise is the frames' (from the fits), the sign is seen; initial_load is the prior's scale
        EstimatorSpec("fullfield", "fvk", False, FullFieldSettings, "DIC full field, FvK membrane", frozenset()),
    )
}


def resolve(
    method: str = "auto",
    model: str = "auto",
    *,
    stream: bool = False,
    simulated: str | None = None,
    frames: bool = False,
):
    """The :class:`EstimatorSpec` of a method and a membrane (``auto`` resolved).

    ``simulated``: the truth physics of a simulated record (``None`` for measured data). ``auto``
    picks the estimator that is right on a real membrane for measured data and for simulated
    nonlinear truth (the FvK membrane, measured in docs/estimation_records.md), the seed's
    linear MHE on the seed's simulated linear protocol, and matches a given membrane. ``frames``:
    the data are DIC frames: ``auto`` is the full-field estimator (another method gets the
    frames' virtual sensors); a frame estimator without frames is refused.
    """
    method = METHOD_ALIASES.get(method, method)
    model = MODEL_ALIASES.get(model, model)
    if method not in METHODS:
        raise InputError(f"method = {method!r}: expected one of {', '.join(METHODS)}")
    if model not in MODELS:
        raise InputError(f"model = {model!r}: expected one of {', '.join(MODELS)}")
    if method in FRAME_METHODS and not frames:
        raise InputError(f"method {method!r} estimates from DIC frames: give them (wingopt identify --dic FRAMES)")
    if method == "auto" and frames and not stream:
        method = "fullfield"
    if model == "auto":
        if method in ("mhe", "jekf-seed", "jekf-tuned"):
            model = "linear"
        elif simulated in ("linear", "berger") and method == "auto":
            model = simulated
        else:
            model = "fvk"
    if method == "auto":
        nonlinear = "ekf" if stream else "batch"
        method = "mhe" if model == "linear" else nonlinear
    spec = REGISTRY.get((method, model, stream))
    if spec is None:
        pairs = ", ".join(f"{m}/{p}" for (m, p, s) in REGISTRY if s == stream)
        kind = "a stream" if stream else "a record"
        raise InputError(f"method {method!r} with the {model} membrane: no such estimator for {kind}; pairs: {pairs}")
    return spec


def check_options(spec: EstimatorSpec, options: IdentifyOptions) -> None:
    """Refuse, in one line, the first option ``spec`` would ignore (naming the option and the pair)."""
    for name in options.given:
        flag = OPTION_FLAGS.get(name, name)
        if name not in spec.options:
            used = ", ".join(sorted(OPTION_FLAGS[o] for o in spec.options))
            raise InputError(f"{flag} is not used by the {spec.label}; its options: {used}")
    for name, applies, reason in spec.requires:
        if name in options.given and not applies(options):
            raise InputError(f"{OPTION_FLAGS[name]} is not used here: {reason}")


def pairs(stream: bool | None = None) -> list[EstimatorSpec]:
    """Every registered estimator (or those that stream, or not)."""
    return [s for s in REGISTRY.values() if stream is None or s.stream == stream]


def replace(spec: EstimatorSpec, **kw) -> EstimatorSpec:
    return dataclasses.replace(spec, **kw)
