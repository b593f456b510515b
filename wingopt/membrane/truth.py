"""Simulated records with their truth: one function of (forward model, load, protocol).

:func:`simulate_truth` runs any :class:`~wingopt.membrane.forward.MembraneForward` (the studies use
the full-order models on a finer mesh than the estimator's: no inverse crime) under a pressure
field times a load factor over time, from the protocol's start, samples the sensors, adds
Gaussian noise of ``p * max_t |s_i(t)|`` per sensor (spec §2) and drops samples if asked. The
:class:`TruthRecord` carries the truth (load, deflection, lift history, parameters) and the error
metrics of spec §2: relative L2 norms over the membrane, not coefficient norms.

Starts: ``"bubble"`` (the seed's 1 cm bubble at rest, spec §2), ``"rest"`` (flat, at rest),
``"static"`` (at rest in the static equilibrium of the load at ``t = 0``: a wing already loaded when
the recording starts, as in a wind tunnel) and ``"shape"`` (at rest in a given deflection field: a
release from a push, a calibration record).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from wingopt.errors import InputError
from wingopt.fe import integrate
from wingopt.measurements import Measurements
from wingopt.membrane.loads import PressureLoad, bubble, load_case
from wingopt.membrane.model import MembraneModel
from wingopt.membrane.sensors import add_noise

__all__ = ["RecordProtocol", "Trajectory", "TruthRecord", "simulate_truth", "relative_l2", "STARTS"]

STARTS = ("bubble", "rest", "static", "shape")


def relative_l2(space, truth, estimate) -> float:
    """``||truth - estimate||_L2 / ||truth||_L2`` over the membrane, both callables ``(x, y)``."""
    num = integrate(space, lambda x, y: (truth(x, y) - estimate(x, y)) ** 2, order=8)
    den = integrate(space, lambda x, y: truth(x, y) ** 2, order=8)
    return float(np.sqrt(num / den))


@dataclass(frozen=True)
class RecordProtocol:
    """How a record is taken.

    Attributes
    ----------
    t_end, dt : float
        Duration and sample period (s); ``dt`` ``None``: the problem's.
    start : {"bubble", "rest", "static"}
    bubble_peak : float
        Peak of the ``"bubble"`` start (m).
    noise_fraction : float
        Noise std as a FRACTION of each sensor's peak clean output (0.01 = 1 %). The former ``noise``
        keyword is refused (:class:`~wingopt.errors.InputError` naming this one).
    seed : int or None
        Noise (and dropped-sample) seed.
    load_factor : callable ``t -> factor``, optional
        Multiplies the pressure field over time (a gust, buffeting); default 1.
    drop : float
        Fraction of samples dropped at random (rows of NaN, as a DAQ's lost frames).
    initial_shape : callable ``(x, y) -> w``, optional
        The deflection of the ``"shape"`` start (m).
    """

    t_end: float = 1.0
    dt: float | None = None
    start: str = "bubble"
    bubble_peak: float = 0.01
    noise_fraction: float = 0.0
    seed: int | None = 0
    load_factor: Callable | None = None
    drop: float = 0.0
    initial_shape: Callable | None = None
    noise: float | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.noise is not None:
            # The unit is in the name now: a bare ``noise`` was a fraction here and a percentage on the
            # command line, and 1 meant 100 % noise in one and 1 % in the other.
            raise InputError(f"noise = {self.noise!r}: give noise_fraction (0.01 = 1 % of each sensor's peak output)")
        if not (np.isfinite(self.t_end) and self.t_end > 0):
            raise InputError(f"t_end = {self.t_end!r}: expected a positive duration (s)")
        if self.dt is not None and not (np.isfinite(self.dt) and self.dt > 0):
            raise InputError(f"dt = {self.dt!r}: expected a positive sample period (s)")
        if self.start not in STARTS:
            raise InputError(f"start = {self.start!r}: expected one of {', '.join(STARTS)}")
        if not (np.isfinite(self.noise_fraction) and 0 <= self.noise_fraction <= 1):
            raise InputError(
                f"noise_fraction = {self.noise_fraction!r}: expected a fraction of the sensors' peak in [0, 1] "
                "(0.01 = 1 %)"
            )
        if not (0 <= self.drop < 1):
            raise InputError(f"drop = {self.drop!r}: expected a fraction of samples in [0, 1)")
        if (self.start == "shape") != (self.initial_shape is not None):
            raise InputError("start = 'shape' goes with an initial_shape (a deflection field), and only it")

    def replace(self, **kw) -> RecordProtocol:
        return dataclasses.replace(self, **kw)


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A simulated run: times ``(N+1,)``, deflection coefficients ``(N+1, n)`` and their velocities
    (``None`` where the model does not keep them), load coefficients held on each step ``(N, n)``
    and clean sensor outputs ``(N+1, p)``."""

    t: np.ndarray
    z: np.ndarray
    zdot: np.ndarray | None
    load: np.ndarray
    outputs: np.ndarray


@dataclass(frozen=True, eq=False)
class TruthRecord:
    """A simulated record and its truth: the load, the truth's model and trajectory, the data.

    ``load`` is the pressure at the end of the record (the shape times the final load factor);
    ``load_factor`` ``(N+1,)`` the factor over time; ``parameters`` the truth's prestrains and damping.
    """

    load: PressureLoad
    truth_model: MembraneModel
    trajectory: Trajectory
    measurements: Measurements
    noise_fraction: float
    seed: int | None
    load_factor: np.ndarray
    parameters: dict
    physics: str
    noise_std: np.ndarray
    shape: PressureLoad | None = None

    def true_deflection(self, k: int = -1):
        """Callable ``(x, y)``: the truth's deflection at sample ``k`` (truth mesh)."""
        return self.truth_model.field(self.trajectory.z[k])

    @property
    def true_lift(self) -> float:
        """``∫ P`` at the end of the record (N)."""
        return integrate(self.truth_model.space, self.load, order=8)

    @property
    def lift_history(self) -> np.ndarray:
        """``∫ P(t)`` at every sample (N)."""
        return self.load_factor * (self.true_lift / float(self.load_factor[-1]))

    @property
    def true_absolute_load(self) -> float:
        """``∫ |P|`` (L2 has zero net lift, so lift errors are scaled by this)."""
        return integrate(self.truth_model.space, lambda x, y: np.abs(self.load(x, y)), order=8)

    def load_error(self, load_field) -> float:
        """Relative L2 error of an estimated pressure field (callable ``(x, y)``) at the end."""
        return relative_l2(self.truth_model.space, self.load, load_field)

    def deflection_error(self, deflection_field, k: int = -1) -> float:
        """Relative L2 error of an estimated deflection field at sample ``k``."""
        return relative_l2(self.truth_model.space, self.true_deflection(k), deflection_field)

    def with_noise(self, noise_fraction: float, seed: int | None, tell: bool = False) -> TruthRecord:
        """The same clean record with other noise, ``noise_fraction`` of each sensor's peak output
        (0.01 = 1 %); ``tell``: the measurements carry its std."""
        noisy, sigma = add_noise(self.trajectory.outputs, noise_fraction, seed)
        noisy[np.isnan(self.measurements.values)] = np.nan
        src = _source(self, noise_fraction, seed)
        meas = dataclasses.replace(self.measurements, values=noisy, noise_std=sigma if tell else None, source=src)
        return dataclasses.replace(self, measurements=meas, noise_fraction=noise_fraction, seed=seed, noise_std=sigma)

    def told(self) -> TruthRecord:
        """The record whose measurements carry the simulated noise std (estimators then need not estimate it)."""
        return dataclasses.replace(self, measurements=dataclasses.replace(self.measurements, noise_std=self.noise_std))


def _source(rec: TruthRecord, noise: float, seed) -> str:
    nx, ny = rec.truth_model.problem.nodes
    p = rec.parameters
    return (
        f"simulated {rec.physics} truth {rec.load.name} {100 * noise:g}% seed {seed} {nx}x{ny} "
        f"e0=({p['prestrain_x']:g},{p['prestrain_y']:g}) d={p['damping']:g}"
    )


def simulate_truth(forward, load: str | PressureLoad, protocol: RecordProtocol = RecordProtocol()) -> TruthRecord:
    """Simulate a sensor record of ``forward`` (any :class:`~wingopt.membrane.forward.MembraneForward`).

    Parameters
    ----------
    forward : MembraneForward
        The truth's model, mesh and parameters (``forward.run`` uses its own parameters).
    load : str or PressureLoad
        A load case by name (:func:`~wingopt.membrane.loads.load_case`) or any pressure field.
    protocol : RecordProtocol

    Returns
    -------
    TruthRecord
        The measurements (noisy, with dropped samples as NaN rows), the truth's trajectory, load,
        lift history and parameters, and the error metrics against them.
    """
    model = forward.model
    problem = model.problem
    if isinstance(load, str):
        load = load_case(load, problem.width, problem.height)
    f = model.project(load)
    dt = problem.identification.dt if protocol.dt is None else float(protocol.dt)
    steps = int(round(protocol.t_end / dt))
    if steps < 1:
        raise InputError(f"t_end = {protocol.t_end!r}: shorter than one sample (dt = {dt:g} s)")
    t = np.arange(steps + 1) * dt
    factor = np.ones(steps + 1) if protocol.load_factor is None else np.asarray(protocol.load_factor(t), float)
    forcing = f if protocol.load_factor is None else (lambda s: float(protocol.load_factor(s)) * f)
    if protocol.start == "bubble":
        z0 = model.project(bubble(problem.width, problem.height, protocol.bubble_peak))
    elif protocol.start == "static":
        z0 = forward.equilibrium(factor[0] * f)
    elif protocol.start == "shape":
        z0 = model.project(protocol.initial_shape)
    else:
        z0 = None
    rec = forward.run(forcing, protocol.t_end, dt=dt, z0=z0)
    clean = rec.outputs
    noisy, sigma = add_noise(clean, protocol.noise_fraction, protocol.seed)
    if protocol.drop:
        rng = np.random.default_rng(None if protocol.seed is None else protocol.seed + 104729)
        lost = rng.random(steps + 1) < protocol.drop
        lost[0] = False
        noisy[lost] = np.nan
    par = rec.params
    parameters = {"prestrain_x": par.eps0_x, "prestrain_y": par.eps0_y, "damping": par.viscous_scale}
    held = np.outer(factor[:-1], f)
    final = float(factor[-1])
    scaled = PressureLoad(load.name, lambda x, y: final * load(x, y), load.description, load.breaks_x, load.breaks_y)
    traj = Trajectory(rec.t, rec.z, rec.zdot, held, clean)
    meas = Measurements(rec.t, noisy, problem.sensor_names, None, "", simulated=True)
    noise = protocol.noise_fraction
    out = TruthRecord(scaled, model, traj, meas, noise, protocol.seed, factor, parameters, forward.physics, sigma, load)
    return dataclasses.replace(
        out, measurements=dataclasses.replace(meas, source=_source(out, protocol.noise_fraction, protocol.seed))
    )
