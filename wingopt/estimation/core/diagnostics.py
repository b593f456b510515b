"""What every estimator says of its own answer, typed: :class:`Diagnostics`.

Each estimator keeps its own detail in ``IdentificationResult.info`` (iterations, the lambda rule,
the checks of its route: a dict, as ``summary.json``'s ``estimator`` block shows it). The part the
layers above read — the warnings, whether the model explains the data and at which chi-square,
whether the solvers converged, the steady lift a steady fit reports, the identified parameters,
the data left out — is one contract between every estimator and every reader (the run's status,
the reported lift, ``summary.json``'s top level, the stream's summary, a study's row). It is read
from ``info`` here, once, into typed fields (``result.diagnostics``), and written back to the keys
``summary.json`` has always had (:meth:`Diagnostics.summary`); no reader looks the keys up itself.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["Diagnostics"]

_SUMMARY_MODEL = "linear"
"""The ``model`` a summary names when the estimator names none (the linear MHE's results)."""


def _float(value) -> float | None:
    return None if value is None else float(value)


def _flag(value) -> bool | None:
    return None if value is None else bool(value)


@dataclass(frozen=True)
class Diagnostics:
    """The diagnostics every estimator's result carries (module docstring).

    Attributes
    ----------
    warnings : tuple of str
        What the estimator warns of its answer (its own checks; the route adds its own beside).
    model : str or None
        The forward model that answered (``"realistic (FvK)"``, ...); ``None``: the linear MHE's.
    model_adequate : bool or None
        Whether the model explains the data (``None``: not checked).
    chi2_per_datum : float or None
        The misfit per datum that verdict rests on (1: the data explained to the noise level).
    converged : bool or None
        Whether the estimator's own iteration converged (``None``: it does not iterate, or says not).
    solver_statuses : tuple of str
        The statuses of the convex solves (:class:`~wingopt.optim.status.SolveStatus` names).
    steady_lift : tuple of (float, float) or None
        ``(lift, 1-sigma)`` (N) of a steady fit (the steady route, the DIC mean field): the lift a
        summary reports instead of the history's last value, which fluctuates about it.
    record : str or None
        What kind of record the route found (``"steady"`` when the steady fit answered).
    parameters, parameters_std : dict or None
        The identified membrane parameters (prestrains, damping factor) and their 1-sigma.
    dropped : tuple
        The data the estimator left out (sensors, samples), each as it describes it.
    """

    warnings: tuple[str, ...] = ()
    model: str | None = None
    model_adequate: bool | None = None
    chi2_per_datum: float | None = None
    converged: bool | None = None
    solver_statuses: tuple[str, ...] = ()
    steady_lift: tuple[float, float] | None = None
    record: str | None = None
    parameters: dict[str, float] | None = None
    parameters_std: dict[str, float] | None = None
    dropped: tuple = ()

    @classmethod
    def of(cls, info: Mapping[str, Any]) -> Diagnostics:
        """The typed diagnostics of an estimator's ``info``."""
        adequacy = info.get("adequacy") or {}
        steady = info.get("steady_lift_N")
        return cls(
            warnings=tuple(str(w) for w in info.get("warnings", ())),
            model=info.get("model"),
            model_adequate=_flag(info.get("model_adequate")),
            chi2_per_datum=_float(adequacy.get("chi2_per_datum")),
            converged=_flag(info.get("converged")),
            solver_statuses=tuple(str(getattr(s, "value", s)) for s in info.get("statuses") or ()),
            steady_lift=None if steady is None else (float(steady), float(info["steady_lift_std_N"])),
            record=info.get("record"),
            parameters=info.get("parameters"),
            parameters_std=info.get("parameters_std"),
            dropped=tuple(info.get("dropped", ())),
        )

    def summary(self) -> dict[str, Any]:
        """The top-level keys of ``summary.json`` these diagnostics fill (the same keys as ever):
        ``model``, ``model_adequate``, ``dropped``, and where the estimator gives them
        ``chi2_per_datum``, ``parameters`` and ``parameters_std``."""
        out: dict[str, Any] = {
            "model": self.model or _SUMMARY_MODEL,
            "model_adequate": self.model_adequate,
            "dropped": list(self.dropped),
        }
        if self.chi2_per_datum is not None:
            out["chi2_per_datum"] = self.chi2_per_datum
        if self.parameters is not None:
            out["parameters"] = self.parameters
            out["parameters_std"] = self.parameters_std
        return out
