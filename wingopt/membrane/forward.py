"""The membrane's forward-model layer: one protocol, every membrane model an implementation of it.

A forward model maps a load history and an initial state to a sensor record, for given
:class:`~wingopt.membrane.parameters.MembraneParameters`. Three physics (spec §2, §8) at two
fidelities:

=========  ==========================================  ===============================================
physics    full order (truth, :mod:`.full`)             reduced, modal (estimators, :mod:`.modal`)
=========  ==========================================  ===============================================
linear     Berger operators, stretch left out           either modal model with ``nonlinear=False``
berger     :class:`~.full.berger.BergerMembrane`        :class:`~.modal.berger.BergerModal`
fvk        :class:`~.full.fvk.FvKMembrane`              :class:`~.modal.fvk.FvKModal` (cubic on the lowest modes)
=========  ==========================================  ===============================================

One integrator per family: the full-order models share the exponential integrator of
:mod:`.full.integrator` (exact for the linear membrane), the modal models the exact-oscillator
predictor-corrector of :mod:`.modal.kernels` (exact for the linear membrane; its exact tangent
gives the sensitivities to load, initial state and parameters). :func:`forward_model` builds any of
them; truth records (:mod:`wingopt.membrane.truth`), estimators and designs consume them through
:class:`MembraneForward`. The estimators take their models here too, and nothing else of
:mod:`.modal` or :mod:`.full`: :func:`modal_model` (built once per wing, cached), :func:`full_model`,
and the types they name (re-exported).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from wingopt.errors import InputError
from wingopt.membrane.full.berger import BergerMembrane
from wingopt.membrane.full.fvk import FvKMembrane
from wingopt.membrane.full.integrator import integrate
from wingopt.membrane.modal.base import ModalMembrane
from wingopt.membrane.modal.berger import BergerModal
from wingopt.membrane.modal.fvk import FvKModal
from wingopt.membrane.modal.sample import ModalSample
from wingopt.membrane.modal.tangent import ForceTangent
from wingopt.membrane.model import MembraneModel
from wingopt.membrane.parameters import MembraneParameters

__all__ = ["PHYSICS", "ForwardRecord", "MembraneForward", "FullOrder", "Reduced", "forward_model"]
__all__ += ["modal_model", "full_model", "FullStructure", "ModalMembrane", "ModalSample", "ForceTangent"]

FullStructure = BergerMembrane | FvKMembrane
"""A full-order membrane structure (what :func:`full_model` builds): the type its users name."""

PHYSICS = ("linear", "berger", "fvk")
"""The membrane physics: the seed's linear membrane, uniform (Berger) tension, Föppl–von Kármán."""


@dataclass(frozen=True, eq=False)
class ForwardRecord:
    """A forward model's response: times ``(N+1,)``, deflection coefficients ``(N+1, n)`` on the
    model's mesh, their velocities (``None`` where the model does not keep them) and the clean
    sensor outputs ``(N+1, p)``."""

    t: np.ndarray
    z: np.ndarray
    zdot: np.ndarray | None
    outputs: np.ndarray
    params: MembraneParameters


class MembraneForward(Protocol):
    """What every membrane forward model offers."""

    physics: str
    model: MembraneModel

    @property
    def reduced(self) -> bool: ...

    def run(
        self, load, t_end: float, *, dt: float | None = None, z0=None, v0=None, params: MembraneParameters | None = None
    ) -> ForwardRecord:
        """Response to ``load`` (coefficients ``(n,)``, a pressure field or ``t -> (n,)``) from ``(z0, v0)``
        (coefficients or fields; default rest) for ``t_end`` s, sampled every ``dt``."""

    def equilibrium(self, f: np.ndarray, params: MembraneParameters | None = None) -> np.ndarray: ...


def _state_input(model: MembraneModel, z):
    """Coefficients of an initial state given as coefficients or a field ``(x, y) -> w`` (projected)."""
    if z is None or isinstance(z, np.ndarray):
        return z
    return model.project(z) if callable(z) else np.asarray(z, dtype=float)


def _load_input(model: MembraneModel, load):
    """Load coefficients ``(n,)`` or a callable ``t -> (n,)`` from coefficients, a field or a callable."""
    if callable(load) and not isinstance(load, np.ndarray):
        try:
            first = np.asarray(load(0.0), dtype=float)
        except TypeError:
            first = None
        if first is not None and first.shape == (model.n,):
            return load
        return model.project(load)
    return np.asarray(load, dtype=float)


@dataclass(frozen=True, eq=False)
class FullOrder:
    """A full-order membrane (every spline coefficient a degree of freedom): the truth's models."""

    physics: str
    structure: FullStructure
    substeps: int = 2
    reduced = False

    @property
    def model(self) -> MembraneModel:
        return self.structure.linear

    def _at(self, params: MembraneParameters | None):
        if params is None or params == self.structure.params:
            return self.structure
        return self.structure.with_params(params)

    def run(self, load, t_end, *, dt=None, z0=None, v0=None, params=None) -> ForwardRecord:
        """Response from ``(z0, v0)`` (coefficients; default rest) sampled every ``dt`` (default: the problem's)."""
        s = self._at(params)
        dt = self.model.problem.identification.dt if dt is None else float(dt)
        z0, v0 = _state_input(self.model, z0), _state_input(self.model, v0)
        rec = integrate(
            s, _load_input(self.model, load), t_end, dt, z0, v0, self.substeps, nonlinear=self.physics != "linear"
        )
        return ForwardRecord(rec.t, rec.z, rec.zdot, self.model.sensors.outputs(rec.z), s.params)

    def equilibrium(self, f, params=None) -> np.ndarray:
        """Static deflection coefficients under load coefficients ``f``."""
        s = self._at(params)
        f = np.asarray(f, dtype=float)
        if self.physics == "linear":
            tx, ty = s.prestress
            import scipy.sparse.linalg as spla  # noqa: PLC0415 - only the linear statics need it

            return spla.spsolve((tx * s.gx + ty * s.gy).tocsc(), s.gram @ f)
        return s.equilibrium(f)


@dataclass(frozen=True, eq=False)
class Reduced:
    """A modal membrane (the estimators' models), integrated at its own sample period."""

    physics: str
    modal: BergerModal | FvKModal
    reduced = True

    @property
    def model(self) -> MembraneModel:
        return self.modal.model

    def run(self, load, t_end, *, dt=None, z0=None, v0=None, params=None) -> ForwardRecord:
        if dt is not None and not np.isclose(dt, self.modal.dt, rtol=1e-9):
            raise InputError(f"dt = {dt!r}: this modal model is built for dt = {self.modal.dt:g} s")
        par = self.modal.nominal if params is None else params
        f = _load_input(self.model, load)
        z0, v0 = _state_input(self.model, z0), _state_input(self.model, v0)
        Z = self.modal.record(f, t_end, z0, v0, par, nonlinear=self.physics != "linear")
        t = np.arange(Z.shape[0]) * self.modal.dt
        return ForwardRecord(t, Z, None, self.model.sensors.outputs(Z), par)

    def equilibrium(self, f, params=None) -> np.ndarray:
        par = self.modal.nominal if params is None else params
        q = self.modal.equilibrium(self.modal.modal_force(np.asarray(f, float)), par, self.physics != "linear")
        return self.modal.deflection(q)


def forward_model(
    problem,
    physics: str = "fvk",
    *,
    reduced: bool = False,
    nodes: tuple[int, int] | None = None,
    params: MembraneParameters | None = None,
    substeps: int = 2,
    modes: int = 48,
    cubic_modes: int = 16,
    dt: float | None = None,
) -> FullOrder | Reduced:
    """Build the membrane forward model of ``physics`` on ``nodes`` (default: the problem's mesh).

    Parameters
    ----------
    problem : MembraneProblem or MembraneModel
    physics : {"linear", "berger", "fvk"}
    reduced : bool
        ``False``: full order (``params`` fixed, ``substeps`` per sample); ``True``: modal with
        ``modes`` modes (FvK: ``cubic_modes`` with the cubic stiffness) at sample period ``dt``.
    nodes : (int, int), optional
        Mesh (default: the problem's or the model's).
    params : MembraneParameters, optional
        The full-order model's parameters (default: the problem file's).

    Returns
    -------
    FullOrder or Reduced
        A :class:`MembraneForward`: ``run(load, t_end, z0=..., v0=...)`` and ``equilibrium(f)``.
    """
    if physics not in PHYSICS:
        raise InputError(f"physics = {physics!r}: expected one of {', '.join(PHYSICS)}")
    model = problem if isinstance(problem, MembraneModel) else MembraneModel.from_problem(problem, nodes)
    if nodes is not None and tuple(model.problem.nodes) != tuple(nodes):
        model = MembraneModel.from_problem(model.problem, nodes)
    if reduced:
        kind = "fvk" if physics == "fvk" else "berger"
        return Reduced(physics, modal_model(model, kind, min(modes, model.n), dt, substeps, cubic_modes=cubic_modes))
    return FullOrder(physics, full_model(model, physics, params), substeps)


def full_model(model: MembraneModel, physics: str = "fvk", params: MembraneParameters | None = None) -> FullStructure:
    """The full-order structure of ``physics`` on ``model``'s mesh (``params`` default: the file's):
    a :class:`~.full.fvk.FvKMembrane` for ``"fvk"``, else a :class:`~.full.berger.BergerMembrane`.
    Not cached: its static solves keep state (a reused tangent)."""
    par = MembraneParameters.nominal(model.problem) if params is None else params
    if physics == "fvk":
        return FvKMembrane.from_model(model, par)
    return BergerMembrane(model, par)


class _Wing:
    """A membrane model as a cache key: what its modal model depends on (geometry, mesh, material,
    sensors), not the identification settings, so a re-read or recalibrated problem file hits."""

    def __init__(self, model: MembraneModel) -> None:
        p = model.problem
        self.model, self.key = model, (p.width, p.height, p.nodes, p.material, p.sensors)

    def __hash__(self) -> int:
        return hash(self.key)

    def __eq__(self, other) -> bool:
        return isinstance(other, _Wing) and self.key == other.key


def modal_model(
    model: MembraneModel,
    physics: str = "fvk",
    modes: int = 48,
    dt: float | None = None,
    substeps: int = 1,
    stretch_gain: float = 1.0,
    cubic_modes: int = 16,
) -> ModalMembrane:
    """The modal model of ``physics`` (``"fvk"``: :class:`~.modal.fvk.FvKModal` with ``cubic_modes``
    cubic modes; ``"berger"``: :class:`~.modal.berger.BergerModal` at ``stretch_gain``) on the
    ``modes`` lowest modes of ``model``, at sample period ``dt`` (default: the problem's) with
    ``substeps`` steps per sample.

    Built once per wing and settings (the FvK tensor of 30 cubic modes takes 1-1.5 s, more than a
    steady record's fit): the modes and the tensor depend neither on ``dt`` and ``substeps`` nor on
    the identification settings, so records at 300 Hz and 1 kHz, a lab's records of one wing and
    the batch and streaming estimators share one build, each with its own ``dt``, ``substeps`` and
    ``model``.
    """
    if physics not in ("fvk", "berger"):
        raise InputError(f"physics = {physics!r}: expected 'fvk' or 'berger' for a modal model")
    if not (isinstance(substeps, (int, np.integer)) and substeps >= 1):
        raise InputError(f"substeps = {substeps!r}: expected an integer >= 1")
    dt = model.problem.identification.dt if dt is None else dt
    if not (np.isfinite(dt) and dt > 0):
        raise InputError(f"dt = {dt!r}: expected a positive sample period (s)")
    if physics == "fvk":
        bm = _modal_model(_Wing(model), physics, modes, None, cubic_modes)
    else:
        bm = _modal_model(_Wing(model), physics, modes, stretch_gain, None)
    return dataclasses.replace(bm, model=model, dt=float(dt), substeps=int(substeps))


@functools.lru_cache(maxsize=4)
def _modal_model(wing: _Wing, physics, modes, stretch_gain, cubic_modes) -> ModalMembrane:
    if physics == "fvk":
        return FvKModal.build(wing.model, modes, cubic_modes=cubic_modes)
    return BergerModal.build(wing.model, modes, stretch_gain=stretch_gain)
