"""Build the FE model of any problem kind: ``build_model(load_problem("membrane"))``."""

from __future__ import annotations

import importlib
from typing import Any, Protocol

import numpy as np

__all__ = ["build_model", "WingModel"]

# kind -> "module:Class"; each class has ``from_problem(problem, nodes=None)``.
_MODEL_CLASSES = {"membrane": "wingopt.membrane.model:MembraneModel", "plate": "wingopt.plate.model:PlateModel"}


class WingModel(Protocol):
    """What every model offers (see :class:`~wingopt.membrane.MembraneModel`)."""

    problem: Any

    def frequencies_hz(self, count: int) -> np.ndarray: ...

    def eigenvalues(self, count: int) -> np.ndarray: ...


def build_model(problem, nodes: tuple[int, int] | None = None) -> WingModel:
    """Assemble the FE model of ``problem`` on its own mesh or on ``nodes``.

    Parameters
    ----------
    problem : MembraneProblem or PlateProblem
        From :func:`wingopt.problem.load_problem`.
    nodes : (int, int), optional
        Mesh nodes in x and y (default: the problem's).

    Returns
    -------
    MembraneModel or PlateModel
        Sparse ``M``, ``K``, damping, inputs and sensors; ``model.system`` is its
        :class:`~wingopt.dynamics.SecondOrderSystem` (modes and static fields cached).
    """
    module, cls = _MODEL_CLASSES[problem.kind].split(":")
    return getattr(importlib.import_module(module), cls).from_problem(problem, nodes)
