"""Simulated sensor records from a geometrically nonlinear membrane: the truth generator.

:func:`simulate_record` mirrors the linear identification protocol (spec §2, seed §6.4;
:mod:`wingopt.estimation.protocol`): the membrane starts from the 1 cm bubble
``g1 = 0.01 * 16 xi (1 - xi) eta (1 - eta)`` at rest, a load is applied for ``t_end`` at
``dt = 1 ms``, the four sensor outputs ``s_i = z^T C_i z`` are taken on the truth mesh and
Gaussian noise of standard deviation ``p * max_t |s_i|`` is added per sensor. On top of it:

* the truth model: ``"fvk"`` (Föppl–von Kármán, default), ``"berger"`` or ``"linear"``;
* prestrain ``(eps0_x, eps0_y)`` off the problem file's, damping scaled;
* a 1-cos gust ``1 + a (1 - cos(2 pi (t - t0)/T))`` on ``[t0, t0 + T]`` multiplying the load;
* the leading-edge load ``LE`` besides L1–L3 and the consistency load.

No file I/O here: callers write what they need (e.g. a CSV for ``wingopt identify --data``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError
from wingopt.fe import integrate
from wingopt.membrane.berger import BergerMembrane
from wingopt.membrane.berger_sim import simulate_berger
from wingopt.membrane.fvk import FvKMembrane
from wingopt.membrane.fvk_sim import simulate_fvk
from wingopt.membrane.loads import LOAD_CASES, PressureLoad, bubble, load_case
from wingopt.membrane.model import MembraneModel
from wingopt.membrane.nonlinear import MembraneParameters
from wingopt.membrane.sensors import add_noise

__all__ = [
    "Gust",
    "NonlinearRecord",
    "simulate_record",
    "truth_load",
    "leading_edge_load",
    "TRUTH_MODELS",
    "TRUTH_LOADS",
]

TRUTH_MODELS = ("fvk", "berger", "linear")
TRUTH_LOADS = LOAD_CASES + ("LE",)


def leading_edge_load(width: float, height: float, amplitude: float = 200.0) -> PressureLoad:
    """One-sign load peaking at a quarter chord: ``A (256/27) xi (1 - xi)^3 sin(pi eta)``.

    Its maximum ``A`` is at ``xi = 1/4``; it vanishes on the frame (like L1) and its lift is
    ``A (256/27)(1/20)(2/pi) W L`` (0.591 N for the default wing and 200 Pa).
    """
    W, L, A = width, height, amplitude
    scale = A * 256.0 / 27.0

    def pressure(x, y):
        xi = x / W
        return scale * xi * (1 - xi) ** 3 * np.sin(np.pi * y / L)

    return PressureLoad("LE", pressure, f"{A:g} (256/27) xi (1-xi)^3 sin(pi eta), peak at xi = 1/4")


def truth_load(name: str, width: float, height: float, amplitude: float = 200.0) -> PressureLoad:
    """The seed's load cases (:func:`~wingopt.membrane.loads.load_case`) and ``LE``."""
    if name == "LE":
        return leading_edge_load(width, height, amplitude)
    if name not in LOAD_CASES:
        raise InputError(f"load = {name!r}: expected one of {', '.join(TRUTH_LOADS)}")
    return load_case(name, width, height, amplitude)


@dataclass(frozen=True)
class Gust:
    """Load factor ``1 + amplitude (1 - cos(2 pi (t - start)/duration))`` on ``[start, start + duration]``.

    The default peaks at +60 % of the steady load 0.1 s after the start.
    """

    start: float = 0.3
    duration: float = 0.2
    amplitude: float = 0.3

    def __post_init__(self) -> None:
        if not (np.isfinite(self.start) and self.start >= 0):
            raise InputError(f"gust start = {self.start!r}: expected a time >= 0 (s)")
        if not (np.isfinite(self.duration) and self.duration > 0):
            raise InputError(f"gust duration = {self.duration!r}: expected a positive duration (s)")
        if not np.isfinite(self.amplitude):
            raise InputError(f"gust amplitude = {self.amplitude!r}: expected a finite number")

    def factor(self, t):
        t = np.asarray(t, dtype=float)
        s = (t - self.start) / self.duration
        inside = (s >= 0) & (s <= 1)
        return np.where(inside, 1.0 + self.amplitude * (1.0 - np.cos(2 * np.pi * s)), 1.0)


@dataclass(frozen=True, eq=False)
class NonlinearRecord:
    """A simulated record and its truth.

    Attributes
    ----------
    t : (N+1,) sample times (s); outputs, values : (N+1, p) clean and noisy sensor outputs
    noise_std : (p,) per-sensor noise std; z : (N+1, n) deflection coefficients (truth mesh)
    load : the pressure shape; load_factor : (N+1,) its factor over time (gust); lift : (N+1,) N
    params : the truth's parameters; truth : model name; model : the linear model of the truth mesh
    """

    t: np.ndarray
    outputs: np.ndarray
    values: np.ndarray
    noise_std: np.ndarray
    z: np.ndarray
    load: PressureLoad
    load_factor: np.ndarray
    lift: np.ndarray
    params: MembraneParameters
    truth: str
    model: MembraneModel
    noise_fraction: float
    seed: int | None
    wall_s: float

    @property
    def sensor_names(self) -> tuple[str, ...]:
        return self.model.problem.sensor_names

    @property
    def steady_lift(self) -> float:
        """``∫ P`` of the load shape (N), without the gust factor."""
        return float(self.lift[0] / self.load_factor[0])

    def deflection_field(self, k: int = -1):
        """Callable ``(x, y)``: the true deflection at sample ``k``."""
        return self.model.field(self.z[k])

    def load_field(self, k: int = -1):
        """Callable ``(x, y)``: the true pressure at sample ``k`` (Pa)."""
        factor = float(self.load_factor[k])
        return lambda x, y: factor * self.load(x, y)

    def to_measurements(self):
        """The noisy record as :class:`wingopt.estimation.data.Measurements` (noise std attached)."""
        from wingopt.estimation.data import Measurements  # lazy: estimation builds on membrane

        src = "{} {} {:g}% seed {} truth {}x{}".format(
            self.truth, self.load.name, 100 * self.noise_fraction, self.seed, *self.model.problem.nodes
        )
        return Measurements(self.t, self.values, self.sensor_names, self.noise_std, src)


def simulate_record(
    problem,
    load: str | PressureLoad = "L1",
    *,
    t_end: float = 1.0,
    dt: float | None = None,
    nodes: tuple[int, int] | None = (49, 25),
    prestrain: tuple[float, float] | None = None,
    damping_scale: float | tuple[float, float] = 1.0,
    gust: Gust | None = None,
    noise: float = 0.0,
    seed: int | None = 0,
    truth: str = "fvk",
    substeps: int = 2,
    bubble_peak: float = 0.01,
) -> NonlinearRecord:
    """Simulate a sensor record of a (nonlinear) membrane from the protocol's bubble start.

    Parameters
    ----------
    problem : MembraneProblem
    load : str or PressureLoad
        ``L1, L2, L3, consistency, LE`` (200 Pa amplitude) or any pressure field.
    t_end, dt : float
        Duration and sample period (default: the problem's ``dt``).
    nodes : (int, int) or None
        Truth mesh (default 49x25, finer than the estimator's 25x13; ``None``: the problem's).
    prestrain : (eps0_x, eps0_y), optional
        Truth prestrains (default: the problem file's, isotropic).
    damping_scale : float or (viscous, kelvin_voigt)
        Factors on the problem's damping.
    gust : Gust, optional
        Load factor over time (default: constant load).
    noise : float
        Noise as a fraction of each sensor's peak clean output (0.01 = 1 %).
    seed : int
        Noise seed.
    truth : {"fvk", "berger", "linear"}
        The model that generates the record. ``linear`` is the linear model with the tension
        ``K_T0 = Tx0 Gx + Ty0 Gy`` of the given prestrains and the same damping.
    substeps : int
        Integration steps per sample (FvK and Berger; the linear model is exact).
    bubble_peak : float
        Peak of the initial bubble (m); 0 starts at rest and flat.
    """
    if truth not in TRUTH_MODELS:
        raise InputError(f"truth = {truth!r}: expected one of {', '.join(TRUTH_MODELS)}")
    if not (np.isfinite(noise) and 0 <= noise <= 1):
        raise InputError(f"noise = {noise!r}: expected a fraction of the sensors' peak in [0, 1] (0.01 = 1 %)")
    dt = problem.identification.dt if dt is None else float(dt)
    if isinstance(load, str):
        load = truth_load(load, problem.width, problem.height)
    params = MembraneParameters.nominal(problem, prestrain, damping_scale)
    t0 = time.perf_counter()
    fvk = FvKMembrane(problem, nodes, params) if truth == "fvk" else None
    linear = fvk.linear if fvk is not None else MembraneModel.from_problem(problem, nodes)
    f = linear.project(load)
    factor = (lambda t: 1.0) if gust is None else (lambda t: float(gust.factor(t)))
    forcing = f if gust is None else (lambda t: factor(t) * f)
    z0 = linear.project(bubble(problem.width, problem.height, bubble_peak)) if bubble_peak else np.zeros(linear.n)
    if truth == "fvk":
        res = simulate_fvk(fvk, forcing, t_end, dt, z0=z0, substeps=substeps)
        t, Z = res.t, res.z
    elif truth == "berger":
        tr = simulate_berger(BergerMembrane(linear, params), forcing, t_end, dt, z0=z0, substeps=substeps)
        t, Z = tr.t, tr.z
    else:  # the linear model with this prestrain and damping (exact for a constant load)
        tr = simulate_berger(BergerMembrane(linear, params), forcing, t_end, dt, z0=z0, nonlinear=False)
        t, Z = tr.t, tr.z
    clean = linear.sensors.outputs(Z)
    noisy, sigma = add_noise(clean, noise, seed)
    lift0 = integrate(linear.space, load, order=8)
    fac = np.asarray(gust.factor(t) if gust is not None else np.ones_like(t), dtype=float)
    return NonlinearRecord(
        t, clean, noisy, sigma, Z, load, fac, lift0 * fac, params, truth, linear, noise, seed, time.perf_counter() - t0
    )
