"""Configuration of the joint EKF (:class:`JEKFSettings`) with its two presets, seed and tuned."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.options import option
from wingopt.problem.membrane import IdentificationSettings

__all__ = ["JEKFSettings", "SEED_MEASUREMENT_VARIANCE", "DEFAULT_PEAK"]


SEED_MEASUREMENT_VARIANCE = 1.0e-4
"""The seed's measurement covariance ``R = 1e-4`` (section 6.4, "for simplicity's sake")."""


DEFAULT_PEAK = 0.01
"""Peak (m) of the seed's initial bubble, used when the problem does not state one."""


_STRUCTURES = ("modal", "dense")


def _as_positive(name: str, value: float, allow_inf: bool = False, allow_zero: bool = False) -> float:
    v = float(value)
    ok = (v > 0 or (allow_zero and v == 0)) and (math.isfinite(v) or (allow_inf and v == math.inf))
    if not ok:
        what = "non-negative" if allow_zero else "positive"
        raise InputError(f"{name} = {value!r}: expected a {what} number" + (" (inf allowed)" if allow_inf else ""))
    return v


@dataclass(frozen=True)
class JEKFSettings:
    """Configuration of the joint EKF.

    Parameters
    ----------
    regularization : float
        ``lambda`` in ``P0_d = (P0d_tilde^-1 + lambda Lam)^-1`` (units ``1/(Pa^2 m^-2)``: it depends
        on the units of ``R`` and ``Lam``, so the seed's ``8.58e14`` does not carry over).
    measurement_variance : float, sequence of float, or None
        ``R`` (diagonal): one variance for all sensors or one per sensor. ``None``: take
        ``Measurements.noise_std**2``, or estimate it from the data when the measurements carry
        none (:func:`wingopt.estimation.core.noise.estimate_noise_std`, setting
        :data:`~wingopt.estimation.core.noise.JEKF_NOISE`). Seed: ``1e-4``.
    initial_load : float or None
        Uniform prior mean of the pressure (Pa), projected onto the load space. ``None``: the
        declared ``initial_load`` (:attr:`declaration`; the seed's 200 Pa); ``0.0``: zero initial load.
    initial_peak : float or None
        Signed peak (m) of the initial bubble ``16 xi (1 - xi) eta (1 - eta)``, the prior mean of
        the initial deflection. It fixes the sign of the estimate (the data are unchanged when the
        initial state and the load both flip). ``None``: the declared
        ``initial_deflection`` when non-zero (the protocol's 1 cm), else 1 cm with
        the sign of :attr:`sign_prior`.
    sign_prior : float or None
        Sign prior of the load (Pa; only its sign is used) when ``initial_peak`` is not known;
        ``None``: ``initial_load`` if non-zero, else the declared ``initial_load``.
    load_std : float
        ``sqrt`` of the diagonal of ``P0d_tilde`` (Pa per coefficient); ``inf`` (default): no
        prior beyond ``lambda Lam``.
    deflection_std, velocity_std : float
        1-sigma of the initial deflection (m) and velocity (m/s) per coefficient: the initial
        state is known up to this (the seed starts the filter at the simulated plant's initial
        condition).
    load_change, load_change_time : float
        Gelb's rule ``Qd = load_change^2 / load_change_time`` (Pa^2/s per coefficient); the
        default ``0`` is the static-load filter (``Qd = 0``).
    modes : int or None
        Keep only the lowest ``modes`` membrane modes (approximate, faster); ``None``: all (exact).
    structure : {"modal", "dense"}
        ``"modal"``: the exact block-diagonal form (fast); ``"dense"``: physical coordinates with
        the dense joint transition (reference; slow on 25x13).
    symmetrize_every : int
        Re-symmetrise ``P`` every this many steps (round-off only: the updates are symmetric in exact
        arithmetic; ``1`` = every step).
    declaration : IdentificationSettings or None
        What the problem file declares for identification (its ``[identification]``: the sample
        period, the noise, the initial load and shape). The builder fills it from the problem
        (:func:`~wingopt.estimation.declaration.with_declaration`), and so does :class:`JointEKF`
        when it is still ``None``; a caller may give its own. The filter reads it here, never the problem.
    """

    regularization: float = field(default=1.0, metadata=option("lam"))
    measurement_variance: float | tuple[float, ...] | None = SEED_MEASUREMENT_VARIANCE
    initial_load: float | None = field(default=None, metadata=option("initial_load"))
    initial_peak: float | None = None
    sign_prior: float | None = None
    load_std: float = math.inf
    deflection_std: float = 1.0e-5
    velocity_std: float = 1.0e-3
    load_change: float = 0.0
    load_change_time: float = 1.0
    modes: int | None = field(default=None, metadata=option("modes"))
    structure: str = "modal"
    symmetrize_every: int = 25
    declaration: IdentificationSettings | None = None

    def __post_init__(self) -> None:
        _as_positive("regularization", self.regularization)
        if self.measurement_variance is not None:
            r = np.atleast_1d(np.asarray(self.measurement_variance, dtype=float))
            if r.ndim != 1 or r.size == 0 or not np.all(np.isfinite(r) & (r > 0)):
                raise InputError(
                    f"measurement_variance = {self.measurement_variance!r}: expected a positive variance "
                    "(one, or one per sensor) or None (from the data)"
                )
        if self.initial_load is not None and not math.isfinite(float(self.initial_load)):
            raise InputError(f"initial_load = {self.initial_load!r}: expected a finite pressure (Pa) or None")
        if self.initial_peak is not None and not (math.isfinite(self.initial_peak) and self.initial_peak != 0):
            raise InputError(f"initial_peak = {self.initial_peak!r}: expected a non-zero peak (m) or None")
        if self.sign_prior is not None and not (math.isfinite(self.sign_prior) and self.sign_prior != 0):
            raise InputError(f"sign_prior = {self.sign_prior!r}: expected a non-zero pressure (Pa) or None")
        _as_positive("load_std", self.load_std, allow_inf=True)
        _as_positive("deflection_std", self.deflection_std, allow_zero=True)
        _as_positive("velocity_std", self.velocity_std, allow_zero=True)
        _as_positive("load_change", self.load_change, allow_zero=True)
        _as_positive("load_change_time", self.load_change_time)
        if self.modes is not None and (int(self.modes) != self.modes or self.modes < 1):
            raise InputError(f"modes = {self.modes!r}: expected a positive integer or None (all modes)")
        if self.structure not in _STRUCTURES:
            raise InputError(f"structure = {self.structure!r}: expected one of {', '.join(_STRUCTURES)}")
        if int(self.symmetrize_every) != self.symmetrize_every or self.symmetrize_every < 1:
            raise InputError(f"symmetrize_every = {self.symmetrize_every!r}: expected a positive integer")

    @classmethod
    def seed(cls, regularization: float = 1.0, **changes: Any) -> JEKFSettings:
        """The seed-faithful filter: ``R = 1e-4``, uniform ``initial_load`` prior (200 Pa), the bubble."""
        return cls(regularization=regularization, **changes)

    @classmethod
    def tuned(cls, regularization: float = 1.0, **changes: Any) -> JEKFSettings:
        """The "tuned" filter: zero initial load, ``R`` from the data's noise level."""
        base = {"initial_load": 0.0, "measurement_variance": None}
        base.update(changes)
        return cls(regularization=regularization, **base)

    def replace(self, **changes: Any) -> JEKFSettings:
        return dataclasses.replace(self, **changes)

    @property
    def process_intensity(self) -> float:
        """Gelb's ``Qd_ii = Δf^2 / Δt`` (Pa^2/s)."""
        return self.load_change**2 / self.load_change_time
