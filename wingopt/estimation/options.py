"""The options of one identification, validated once, as one value type.

:class:`IdentifyOptions` holds what the user said (``None``: not said, the estimator's default).
The command line and :func:`wingopt.identify` build it; the registry
(:mod:`wingopt.estimation.registry`) refuses every option the chosen (estimator, membrane) pair
does not use and turns the rest into that estimator's settings. Each option has one name
(:data:`OPTION_FLAGS` maps it to its command-line flag, for messages).
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from wingopt.errors import InputError
from wingopt.optim.registry import check_solver
from wingopt.values import LambdaChoice

__all__ = [
    "IdentifyOptions",
    "OPTION_FLAGS",
    "LOAD_MODELS",
    "parse_duration",
    "option",
    "declared_options",
    "apply_options",
]

LOAD_MODELS = ("auto", "constant", "varying")
"""How the load may change in time: ``constant`` (a steady load), ``varying`` (a load that follows
gusts: the MHE's random walk, the batch estimator's gust amplitude), ``auto`` (the estimator's own
choice). ``random_walk`` and ``gust`` are accepted for ``varying``."""

_LOAD_MODEL_ALIASES = {"random_walk": "varying", "gust": "varying"}

OPTION_FLAGS = {
    "lam": "--lambda/--lambda-rule",
    "window": "--window",
    "stride": "--stride",
    "solver": "--solver",
    "qp_solver": "--qp-solver",
    "modes": "--modes",
    "load_model": "--load-model",
    "load_timescale": "--load-timescale",
    "state_prior": "--state-prior",
    "pressure_bounds": "--pressure-bounds",
    "load_space": "--load-space",
    "consistency": "--no-consistency",
    "noise_std": "--noise-std",
    "initial_load": "--initial-load",
    "model_form": "--no-model-form",
}
"""Every identification option and its command-line flag."""


def parse_duration(text, name: str) -> float | int:
    """``"0.2s"``/``"200ms"`` -> seconds (float); ``"200"`` or ``200`` -> samples (int)."""
    if isinstance(text, bool):
        raise InputError(f"{name} = {text!r}: expected seconds with a unit (0.2s, 200ms) or whole samples (200)")
    if isinstance(text, int):
        if text < 1:
            raise InputError(f"{name} = {text!r}: expected at least one sample")
        return text
    s = str(text).strip().lower()
    m = re.fullmatch(r"([0-9]*\.?[0-9]+(?:e[-+]?[0-9]+)?)\s*(s|ms)?", s)
    if not m:
        raise InputError(f"{name} = {text!r}: expected seconds with a unit (0.2s, 200ms) or whole samples (200)")
    value, unit = float(m.group(1)), m.group(2)
    if unit is None:
        if value != int(value) or value < 1:
            raise InputError(f"{name} = {text!r}: a bare number is samples (a whole number); add 's' for seconds")
        return int(value)
    seconds = value / 1000.0 if unit == "ms" else value
    if not seconds > 0:
        raise InputError(f"{name} = {text!r}: expected a positive duration")
    return seconds


def _positive(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} = {value!r}: expected a positive number") from None
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{name} = {value!r}: expected a positive finite number")
    return v


def _choice(name: str, value: str, allowed: tuple[str, ...]) -> str:
    if value not in allowed:
        raise InputError(f"{name} = {value!r}: expected one of {', '.join(allowed)}")
    return value


@dataclass(frozen=True)
class IdentifyOptions:
    """What the user asked of one identification; ``None`` everywhere means "the estimator's default".

    Attributes
    ----------
    lam : LambdaChoice
        A fixed Tikhonov weight or a data-only rule (:mod:`wingopt.estimation.core.lambda_rules`).
    window, stride : float (s) or int (samples)
        Moving-horizon window and step.
    solver : {"numpy", "cvxpy", "ipopt"}
        The moving-horizon window solver; ``qp_solver`` the QP solver of ``cvxpy``.
    modes : int
        Membrane modes the estimator keeps.
    load_model : {"auto", "constant", "varying"}
    load_timescale : float
        Time (s) over which a varying load may change by its own size.
    state_prior : float or "evidence"
        Prior std of the initial modal state relative to the data's amplitude.
    pressure_bounds : (float, float)
        Bounds on the pressure (Pa).
    load_space : {"fixed", "free"}
    consistency : bool
        ``False``: no chi-square consistency tests (no skipped onset, no restarts).
    noise_std : float
        Sensor noise std (sensor units), when known.
    initial_load : float
        Sign prior (Pa): the sign of the load.
    model_form : bool
        ``False``: a flagged linear-MHE result is not cross-checked with the FvK estimator.
    """

    lam: LambdaChoice | None = None
    window: float | int | None = None
    stride: float | int | None = None
    solver: str | None = None
    qp_solver: str | None = None
    modes: int | None = None
    load_model: str | None = None
    load_timescale: float | None = None
    state_prior: float | str | None = None
    pressure_bounds: tuple[float, float] | None = None
    load_space: str | None = None
    consistency: bool | None = None
    noise_std: float | None = None
    initial_load: float | None = None
    model_form: bool | None = None

    def __post_init__(self) -> None:
        set_ = lambda name, v: object.__setattr__(self, name, v)  # noqa: E731 - frozen dataclass
        if self.lam is not None and not isinstance(self.lam, LambdaChoice):
            raise InputError(f"lambda = {self.lam!r}: expected a LambdaChoice (a fixed value or a rule name)")
        for name in ("window", "stride"):
            if getattr(self, name) is not None:
                set_(name, parse_duration(getattr(self, name), name))
        if self.solver is not None:
            check_solver(self.solver, "window", "solver")
        if self.qp_solver is not None:
            check_solver(self.qp_solver, "least-distance", "qp_solver")
        if self.modes is not None:
            if isinstance(self.modes, bool) or not isinstance(self.modes, int) or self.modes < 1:
                raise InputError(f"modes = {self.modes!r}: expected a positive whole number of membrane modes")
        if self.load_model is not None:
            lm = _LOAD_MODEL_ALIASES.get(self.load_model, self.load_model)
            set_("load_model", _choice("load_model", lm, LOAD_MODELS + tuple(_LOAD_MODEL_ALIASES)))
        if self.load_timescale is not None:
            set_("load_timescale", _positive("load_timescale", self.load_timescale))
        if self.state_prior is not None and self.state_prior != "evidence":
            sp = str(self.state_prior).strip().lower()
            set_("state_prior", "evidence" if sp == "evidence" else _positive("state_prior", self.state_prior))
        if self.pressure_bounds is not None:
            try:
                lo, hi = (float(v) for v in self.pressure_bounds)
            except (TypeError, ValueError):
                raise InputError(f"pressure_bounds = {self.pressure_bounds!r}: expected (min, max) in Pa") from None
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise InputError(f"pressure_bounds = {self.pressure_bounds!r}: expected finite min < max (Pa)")
            set_("pressure_bounds", (lo, hi))
        if self.load_space is not None:
            _choice("load_space", self.load_space, ("fixed", "free"))
        if self.noise_std is not None:
            sd = _positive("noise_std", self.noise_std)
            if not 1e-12 <= sd <= 0.5:  # stretch units: readings are 1e-4..1e-1, 0.5 is refused as a reading
                raise InputError(f"noise_std = {self.noise_std!r}: expected a sensor noise std from 1e-12 to 0.5")
            set_("noise_std", sd)
        if self.initial_load is not None:
            try:
                p0 = float(self.initial_load)
            except (TypeError, ValueError):
                p0 = float("nan")
            if not (math.isfinite(p0) and p0 != 0 and abs(p0) < 1e7):
                raise InputError(
                    f"initial_load = {self.initial_load!r}: expected a non-zero pressure below 1e7 Pa; its sign "
                    "fixes the load's"
                )
            set_("initial_load", p0)

    @property
    def given(self) -> dict:
        """The options the user gave (not ``None``), by name."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if getattr(self, f.name) is not None}

    def as_dict(self) -> dict:
        """The given options as JSON-ready values (recorded in ``summary.json``)."""
        out = {}
        for name, value in self.given.items():
            if isinstance(value, LambdaChoice):
                value = {"value": value.value} if value.is_fixed else {"rule": value.rule}
            out[name] = list(value) if isinstance(value, tuple) else value
        return out

    def replace(self, **kw) -> IdentifyOptions:
        return dataclasses.replace(self, **kw)

    @classmethod
    def merged(cls, options: IdentifyOptions | None, **arguments) -> IdentifyOptions:
        """``options`` (default: none given) with the ``arguments`` that are not ``None`` folded in; an
        option given both ways is refused (:class:`InputError`): which one counts would be a guess."""
        opts = options if options is not None else cls()
        if not isinstance(opts, cls):
            raise InputError(f"options = {type(opts).__name__}: expected wingopt.estimation.options.IdentifyOptions")
        extra = {k: v for k, v in arguments.items() if v is not None}
        both = sorted(set(extra) & set(opts.given))
        if both:
            raise InputError(f"{both[0]}: given both as an argument and in options; give it once")
        return opts.replace(**extra) if extra else opts


_OPTION = "identify_option"


def option(
    name: str | None = None, convert: Callable[[Any], dict[str, Any]] | None = None, *, uses: tuple[str, ...] = ()
) -> dict:
    """Metadata of an estimator's settings field that the identification option ``name`` sets.

    ``convert`` maps the option's value to the settings fields it sets (default: this field, to the
    value itself). A field holding nested settings declares, with ``uses`` (and no ``name``), the
    options of :class:`IdentifyOptions` that reach them: its own settings declare how. This is how
    an estimator's settings dataclass says which options it takes: the registry derives every
    estimator's options from it (:func:`declared_options`).
    """
    names = (*uses, *([name] if name else []))
    if (name is None) == (not uses) or any(n not in OPTION_FLAGS for n in names):
        raise ValueError(f"option({name!r}, uses={uses!r}): expected an IdentifyOptions field, or nested ones")
    return {_OPTION: name, "convert": convert, "uses": tuple(uses)}


def declared_options(settings_type: type) -> frozenset[str]:
    """The :class:`IdentifyOptions` fields that the settings dataclass ``settings_type`` takes."""
    out: set[str] = set()
    for f in dataclasses.fields(settings_type):
        if _OPTION in f.metadata:
            out.update(f.metadata["uses"] or (f.metadata[_OPTION],))
    return frozenset(out)


def apply_options(settings, options: IdentifyOptions, only: tuple[str, ...] | None = None):
    """``settings`` with the options it declares (those of ``options`` given; ``only``: these names) applied."""
    changes: dict[str, Any] = {}
    for f in dataclasses.fields(settings):
        meta = f.metadata
        if _OPTION not in meta:
            continue
        if meta["uses"]:
            changes[f.name] = apply_options(getattr(settings, f.name), options, meta["uses"])
            continue
        value = getattr(options, meta[_OPTION])
        if value is None or (only is not None and meta[_OPTION] not in only):
            continue
        changes.update(meta["convert"](value) if meta["convert"] else {f.name: value})
    return dataclasses.replace(settings, **changes) if changes else settings
