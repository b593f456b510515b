"""Build the FE model of any problem kind: ``build_model(load_problem("membrane"))``."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from wingopt.membrane.model import MembraneModel
from wingopt.plate.model import PlateModel

__all__ = ["build_model", "WingModel"]

_MODEL_CLASSES = {"membrane": MembraneModel, "plate": PlateModel}
"""Problem kind -> model class; each class has ``from_problem(problem, nodes=None)``."""


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
    from wingopt.problem import as_problem

    problem = as_problem(problem)
    return _MODEL_CLASSES[problem.kind].from_problem(problem, nodes)
