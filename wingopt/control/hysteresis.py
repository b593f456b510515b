"""Piezo patches as they are: rate-independent hysteresis (Prandtl-Ishlinskii) and creep, plant only.

Macro-fibre composites driven over -500 ... +1500 V show 10-20 % hysteresis and a slow creep after
each step; no controller model of the package has either. :class:`PatchActuator` sits between the
voltage the harness applies and the one the patches act with
(:func:`wingopt.control.closed_loop.simulate_closed_loop`'s ``actuator``)::

    y   = (1 - W) u + sum_i w_i  play_{r_i}[u]          (Prandtl-Ishlinskii, per patch)
    u_a = y + creep * c,     c' = (y - c) / creep_time  (one creep mode, exact over each period)

``play_r`` is the backlash (play) operator of threshold ``r``: its output follows the input with a
lag of ``r`` and holds when the input turns (rate-independent: only the order of the inputs
matters). Thresholds ``r_i = i / n * S / 4`` (``S = vmax - vmin``) and equal weights ``w_i``
chosen so that the *major loop* (``vmin -> vmax -> vmin``) has the declared ``width``: each play's
branches are ``2 r_i`` apart on ``[vmin + 2 r_i, vmax - 2 r_i]`` (all contain mid-range, since
``r_i <= S/4``), so the largest gap over ``S`` is ``sum_i 2 w_i r_i / S`` and
``w_i = 4 width / (n + 1)`` makes it exact (:func:`major_loop_width` measures it).
Creep (after a voltage step, the strain keeps growing by ``creep`` of it over ``creep_time``) is
the logarithmic creep of piezoceramics reduced to one first-order mode: enough to make a
constant offset that a controller without integral action cannot remove.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError

__all__ = ["HysteresisSettings", "PatchActuator", "major_loop_width"]


@dataclass(frozen=True)
class HysteresisSettings:
    """Parameters of the patch hysteresis and creep (the same for every patch).

    Attributes
    ----------
    width : float
        Major-loop width as a fraction of the voltage range (0: none; 0.10-0.20 for MFCs).
    creep : float
        Creep gain: the extra acting voltage, as a fraction, after a step has settled (0: none).
    creep_time : float
        Creep time constant (s).
    operators : int
        Play operators of the Prandtl-Ishlinskii model.
    """

    width: float = 0.15
    creep: float = 0.0
    creep_time: float = 0.3
    operators: int = 5

    def __post_init__(self) -> None:
        if not (np.isfinite(self.width) and 0.0 <= self.width <= 0.5):
            raise InputError(f"hysteresis width = {self.width!r}: expected a fraction of the range in [0, 0.5]")
        if not (np.isfinite(self.creep) and 0.0 <= self.creep <= 1.0):
            raise InputError(f"creep = {self.creep!r}: expected a fraction in [0, 1]")
        if not (np.isfinite(self.creep_time) and self.creep_time > 0):
            raise InputError(f"creep_time = {self.creep_time!r}: expected a positive time constant (s)")
        if isinstance(self.operators, bool) or not isinstance(self.operators, (int, np.integer)) or self.operators < 1:
            raise InputError(f"operators = {self.operators!r}: expected a positive whole number of play operators")
        if 4.0 * self.width / (self.operators + 1) * self.operators > 1.0:
            raise InputError(f"hysteresis width = {self.width!r}: too wide for {self.operators} play operators")

    @property
    def active(self) -> bool:
        return self.width > 0 or self.creep > 0


class PatchActuator:
    """Hysteresis and creep of ``m`` patches between the applied and the acting voltage (V).

    Parameters
    ----------
    settings : HysteresisSettings
    vmin, vmax : float
        The voltage range that sets the play thresholds (the patches' limits).
    m : int
        Number of patches.
    """

    def __init__(self, settings: HysteresisSettings, vmin: float, vmax: float, m: int) -> None:
        if not (np.isfinite(vmin) and np.isfinite(vmax) and vmin < vmax):
            raise InputError(f"hysteresis: vmin = {vmin!r}, vmax = {vmax!r}: expected finite limits, vmin < vmax")
        self.settings = settings
        n = int(settings.operators)
        span = float(vmax - vmin)
        self.thresholds = np.arange(1, n + 1) / n * span / 4.0
        self.weights = np.full(n, 4.0 * settings.width / (n + 1))
        self.m = int(m)
        self.reset()

    def reset(self) -> None:
        """Virgin state: every play operator and the creep at 0 V."""
        self._play = np.zeros((self.m, self.thresholds.size))
        self._creep = np.zeros(self.m)

    def hysteresis(self, u: np.ndarray) -> np.ndarray:
        """The Prandtl-Ishlinskii output for the next input ``u`` (advances the play operators)."""
        u = np.asarray(u, dtype=float).reshape(self.m, 1)
        r = self.thresholds[None, :]
        self._play = np.minimum(np.maximum(self._play, u - r), u + r)
        return (1.0 - self.weights.sum()) * u[:, 0] + self._play @ self.weights

    def steady_range(self, vmin: float, vmax: float) -> tuple[float, float]:
        """The steady acting voltages reachable with applied voltages in ``[vmin, vmax]``.

        A play operator's state never exceeds ``max(input) - r`` nor falls below ``min(input) + r``,
        so the Prandtl-Ishlinskii output at the limits is ``vmax - sum w_i r_i`` and
        ``vmin + sum w_i r_i`` (``= vmax - width S / 2``, ...), every value between them reachable; a
        settled creep multiplies it by ``1 + creep``. The plant's best shape is the static optimum
        within this range (:func:`wingopt.workflows.morph_plant.plant_extras`).
        """
        shrink = float(self.weights @ self.thresholds)
        gain = 1.0 + self.settings.creep
        return (vmin + shrink) * gain, (vmax - shrink) * gain

    def apply(self, u: np.ndarray, dt: float) -> np.ndarray:
        """Acting voltage over the next ``dt`` s given the applied ``u`` (harness protocol)."""
        y = self.hysteresis(u)
        st = self.settings
        if st.creep > 0:
            a = 1.0 - np.exp(-dt / st.creep_time)
            self._creep = self._creep + a * (y - self._creep)
            return y + st.creep * self._creep
        return y


def major_loop_width(actuator: PatchActuator, vmin: float, vmax: float, points: int = 401) -> float:
    """Largest gap between the descending and ascending branches of ``vmin -> vmax -> vmin``, over the range.

    Measured by driving the operators (creep left out): the check of the declared ``width``.
    """
    actuator.reset()
    up = np.linspace(vmin, vmax, points)
    for u in np.linspace(0.0, vmin, points):  # from the virgin state down to the loop's start
        actuator.hysteresis(np.full(actuator.m, u))
    asc = np.array([actuator.hysteresis(np.full(actuator.m, u))[0] for u in up])
    desc = np.array([actuator.hysteresis(np.full(actuator.m, u))[0] for u in up[::-1]])[::-1]
    actuator.reset()
    return float(np.max(desc - asc) / (vmax - vmin))
