"""What a problem file declares for identification, read once: the door into estimator settings.

A problem's ``[identification]`` table (:class:`~wingopt.problem.membrane.IdentificationSettings`:
the noise, the initial load and shape, the parameter priors and a calibration's posterior, the
pressure prior, the leading edge) is what the lab declares about its rig. Every estimator's
settings carry it in one field, ``declaration``, filled here by the builder
(:func:`~wingopt.estimation.runners.settings_for`) or at an engine's entry when the engine is
called directly; engines read ``settings.declaration``, never ``problem.identification``, so that a
declaration travels one way and can be seen (and replaced) in the settings an estimate ran with.
"""

from __future__ import annotations

import dataclasses
from typing import TypeVar

from wingopt.problem.membrane import IdentificationSettings

__all__ = ["declaration_of", "with_declaration"]

S = TypeVar("S")


def declaration_of(problem) -> IdentificationSettings:
    """The problem's ``[identification]`` declaration (the package's one read of it)."""
    return problem.identification


def with_declaration(settings: S, problem) -> S:
    """``settings`` with ``declaration`` filled from ``problem`` (kept when the caller gave one)."""
    if getattr(settings, "declaration", None) is not None:
        return settings
    return dataclasses.replace(settings, declaration=declaration_of(problem))
