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
predictor-corrector of :mod:`.modal` (exact for the linear membrane; its exact tangent gives the
sensitivities to load, initial state and parameters). :func:`forward_model` builds any of them;
truth records (:mod:`wingopt.membrane.truth`), estimators and designs consume them through
:class:`MembraneForward`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from wingopt.errors import InputError
from wingopt.membrane.full.berger import BergerMembrane
from wingopt.membrane.full.fvk import FvKMembrane
from wingopt.membrane.full.integrator import integrate
from wingopt.membrane.modal.berger import BergerModal
from wingopt.membrane.modal.fvk import FvKModal
from wingopt.membrane.model import MembraneModel
from wingopt.membrane.parameters import MembraneParameters

__all__ = ["PHYSICS", "ForwardRecord", "MembraneForward", "FullOrder", "Reduced", "forward_model"]

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
    structure: BergerMembrane | FvKMembrane
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
        modes = min(modes, model.n)
        if physics == "fvk":
            return Reduced(physics, FvKModal.build(model, modes, dt=dt, substeps=substeps, cubic_modes=cubic_modes))
        return Reduced(physics, BergerModal.build(model, modes, dt=dt, substeps=substeps))
    par = MembraneParameters.nominal(model.problem) if params is None else params
    if physics == "fvk":
        return FullOrder(physics, FvKMembrane.from_model(model, par), substeps)
    return FullOrder(physics, BergerMembrane(model, par), substeps)
