"""Settings of the full-field (DIC) estimator, one frozen value type."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.core.load_prior import PriorScales
from wingopt.estimation.options import option
from wingopt.problem.membrane import IdentificationSettings

__all__ = ["FullFieldSettings", "MODES", "PRIORS", "AUTO_PRIORS", "PRESTRAIN"]

MODES = ("auto", "steady", "frames")
"""``steady``: the frames averaged, one static fit; ``frames``: the steady fit, then every frame's own
load (inertia included); ``auto``: ``frames`` when there are several frames, else ``steady``."""

_MODE = {"constant": "steady", "varying": "frames"}
"""The identification option's load model -> the mode (a steady load: the frames averaged)."""

PRIORS = ("interior", "frame", "aerodynamic")
"""Load priors: zero on the frame; acting up to it (free-edge shapes); thin-airfoil shapes
(:mod:`~wingopt.estimation.core.load_prior`)."""

AUTO_PRIORS = ("interior", "frame")
"""The load priors of a problem file that declares ``pressure_prior = "auto"``: 800 points tell a
load that vanishes on the frame from one that acts up to it (docs/dic.md)."""

PRESTRAIN = ("auto", "prior", "dynamics", "fit")
"""``prior``: the prestrains are the prior's (the problem file's, or a calibration's) and their
uncertainty is carried into the band; ``dynamics``: the frames' response to the buffeting fixes
their lift combination (:mod:`.tension`; the prior where the record has too little dynamics);
``auto``: ``dynamics`` in the time-resolved mode without a calibration, else ``prior`` (with a
calibration the frames' valley pulled the prestrains 13 % off and the lift from +0.5 % to +0.8 %
on the stand-in); ``fit``: the steady field's own pull
on them is added (it comes only through the load prior's smoothness and misleads: docs/dic.md)."""


@dataclass(frozen=True)
class FullFieldSettings:
    """Settings of :func:`~wingopt.estimation.fullfield.fullfield_identify`.

    Attributes
    ----------
    mode : {"auto", "steady", "frames"}
    priors : tuple of str or None
        Load priors fitted and weighed by their evidence (:data:`PRIORS`); ``None``: the problem
        file's ``[identification] pressure_prior``, :data:`AUTO_PRIORS` where it says ``auto``.
    shapes, edge_shapes : int
        Interior load shapes (smoothest, zero on the frame) and free-edge ones more (the ``frame``
        prior; ``0``: :data:`~wingopt.estimation.core.frame_check.FRAME_SHAPES`): 800 points resolve
        far more than four sensors.
    pressure : float or None
        Prior pressure scale (Pa); ``None``: ``|initial_load|`` (the problem file's).
    kappa : float
        Factor on the load prior's std.
    prestrain : {"auto", "prior", "dynamics", "fit"}
        See :data:`PRESTRAIN`.
    smoothing : float
        Curvature penalty of the frame fits, relative to the data's normal matrix.
    inertia : bool
        Time-resolved mode: the membrane's inertia and damping forces (from the fitted frames'
        time derivatives) are part of each frame's load balance.
    min_valid : float
        Fraction of the points a frame needs valid to be used.
    leading_edge : {"x0", "x1"} or None
        The aerodynamic prior's leading edge (``None``: the problem file's, else both).
    modes : bool
        Time-resolved mode, a record that fluctuates: the first two loaded frequencies measured from
        the frames' modal spectra, against the model's, and what they say about the prestrains
        (:mod:`.modes`; ``info["loaded_modes"]``, about 1 s of CPU).
    declaration : IdentificationSettings or None
        The problem file's ``[identification]`` (prior pressure, prestrain prior, pressure prior,
        leading edge): filled by the builder from the problem file, or at the estimator's entry
        (:func:`~wingopt.estimation.declaration.with_declaration`); read nowhere else.
    """

    mode: str = field(default="auto", metadata=option("load_model", lambda v: {"mode": _MODE.get(v, "auto")}))
    priors: tuple[str, ...] | None = None
    shapes: int = 40
    edge_shapes: int = 20
    pressure: float | None = field(default=None, metadata=option("initial_load", lambda v: {"pressure": abs(v)}))
    kappa: float = 1.0
    prestrain: str = "auto"
    smoothing: float = 1e-8
    inertia: bool = True
    min_valid: float = 0.5
    leading_edge: str | None = None
    modes: bool = True
    declaration: IdentificationSettings | None = None

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise InputError(f"mode = {self.mode!r}: expected one of {', '.join(MODES)}")
        if self.priors is not None and (not self.priors or any(p not in PRIORS for p in self.priors)):
            raise InputError(f"priors = {self.priors!r}: expected some of {', '.join(PRIORS)}")
        if self.prestrain not in PRESTRAIN:
            raise InputError(f"prestrain = {self.prestrain!r}: expected one of {', '.join(PRESTRAIN)}")
        for name in ("shapes", "edge_shapes"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < (1 if name == "shapes" else 0):
                raise InputError(f"{name} = {v!r}: expected a whole number >= {1 if name == 'shapes' else 0}")
        for name in ("kappa", "smoothing"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"{name} = {v!r}: expected a positive number")
        if self.pressure is not None and not (np.isfinite(self.pressure) and self.pressure != 0):
            raise InputError(f"pressure = {self.pressure!r}: expected a non-zero pressure (Pa)")
        if not 0 < self.min_valid <= 1:
            raise InputError(f"min_valid = {self.min_valid!r}: expected a fraction in (0, 1]")
        if self.leading_edge not in (None, "x0", "x1"):
            raise InputError(f"leading_edge = {self.leading_edge!r}: expected 'x0', 'x1' or None")

    def replace(self, **kw) -> FullFieldSettings:
        return dataclasses.replace(self, **kw)

    @property
    def prior_scales(self) -> PriorScales:
        """The sizes and scales of its load priors (the interior shapes' std decays as ``mu_1 / mu_s``)."""
        return PriorScales(self.shapes, self.kappa, 1.0, self.edge_shapes)
