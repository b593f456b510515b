"""Which load priors a record is fitted under: the one builder of the estimators' load priors.

A load prior is a set of load shapes with their prior (:class:`~.load_model.LoadShapes`). The
record fits (transient and steady) and the full-field fit differ in which priors ``auto`` weighs,
since their data tell different loads apart; what each prior is, and what the problem file's
``[identification]`` declaration asks for, is said here once:

* ``interior``: the ``shapes`` smoothest shapes, zero on the frame;
* ``frame``: those and ``edge_shapes`` free-edge shapes more (:data:`.frame_check.FRAME_SHAPES`
  where the settings give none): a load that acts up to the frame;
* ``aerodynamic``: the thin-airfoil shapes (:meth:`~.load_model.LoadShapes.aerodynamic`) at the
  declared leading edge, or at each of :data:`EDGES` when the declaration does not say
  (``"aerodynamic x0"``, ``"aerodynamic x1"``).

The declaration's ``pressure_prior`` picks one of them; its ``auto`` leaves the choice to the
estimator's own set (:func:`prior_kinds`).
"""

from __future__ import annotations

from dataclasses import dataclass

from wingopt.errors import InputError
from wingopt.estimation.core.frame_check import FRAME_SHAPES
from wingopt.estimation.core.load_model import LoadShapes
from wingopt.membrane import MembraneModel
from wingopt.problem.membrane import IdentificationSettings

__all__ = ["PriorScales", "EDGES", "KINDS", "prior_kinds", "leading_edges", "load_priors"]

EDGES = ("x0", "x1")
"""Where the leading edge may be when the problem file does not say: ``x = 0`` or ``x = W``."""

KINDS = ("interior", "frame", "aerodynamic")
"""The load priors :func:`load_priors` builds."""


@dataclass(frozen=True)
class PriorScales:
    """The sizes and scales of the load priors, as an estimator's settings give them.

    Attributes
    ----------
    shapes : int
        Interior shapes (the smoothest, zero on the frame) of the ``interior`` and ``frame`` priors.
    kappa : float
        Factor on every prior's std.
    power : float
        Decay of the interior shapes' prior std with roughness, ``(mu_1 / mu_s)^power``.
    edge_shapes : int
        Free-edge shapes of the ``frame`` prior (``0``: :data:`~.frame_check.FRAME_SHAPES`).
    """

    shapes: int
    kappa: float = 1.0
    power: float = 1.0
    edge_shapes: int = 0

    @classmethod
    def of(cls, settings) -> PriorScales:
        """The scales of a record fit's settings (:class:`~.record_settings.RecordSettings`)."""
        return cls(settings.shapes, settings.kappa, settings.prior_power, settings.edge_shapes)


def prior_kinds(declaration: IdentificationSettings, auto: tuple[str, ...]) -> tuple[str, ...]:
    """The priors a record is fitted under: the declared ``pressure_prior``, or the estimator's own
    ``auto`` set where the declaration leaves it to the estimator (``"auto"``)."""
    kind = declaration.pressure_prior
    return tuple(auto) if kind == "auto" else (kind,)


def leading_edges(declared: str | None) -> tuple[str, ...]:
    """The leading edges an aerodynamic prior is built at: the declared one, else both."""
    return (declared,) if declared else EDGES


def load_priors(
    model: MembraneModel,
    kinds: tuple[str, ...],
    pressure: float,
    scales: PriorScales,
    leading_edge: str | None = None,
) -> list[tuple[str, LoadShapes]]:
    """The load priors ``kinds`` (some of :data:`KINDS`), labelled, in that order.

    Parameters
    ----------
    model : MembraneModel
        The estimator's membrane (its deflection basis and frame).
    kinds : tuple of str
        ``interior``, ``frame``, ``aerodynamic`` (module docstring); see :func:`prior_kinds`.
    pressure : float
        The prior pressure scale (Pa; the declaration's ``initial_load`` unless given).
    scales : PriorScales
        Shapes, std factor and decay.
    leading_edge : {"x0", "x1"} or None
        The aerodynamic prior's leading edge (``None``: one prior at each).

    Returns
    -------
    list of (str, LoadShapes)
        ``"interior"``, ``"frame"``, ``"aerodynamic x0"``, ``"aerodynamic x1"``.
    """
    out = []
    for kind in kinds:
        if kind == "interior":
            shapes = LoadShapes.build(model, scales.shapes, pressure, scales.kappa, scales.power)
            out.append(("interior", shapes))
        elif kind == "frame":
            edges = scales.edge_shapes or FRAME_SHAPES
            shapes = LoadShapes.build(model, scales.shapes, pressure, scales.kappa, scales.power, edges)
            out.append(("frame", shapes))
        elif kind == "aerodynamic":
            for edge in leading_edges(leading_edge):
                out.append((f"aerodynamic {edge}", LoadShapes.aerodynamic(model, pressure, edge, scales.kappa)))
        else:
            raise InputError(f"load prior {kind!r}: expected one of {', '.join(KINDS)}")
    return out
