"""Does the record start from the declared initial shape?

``[identification] initial_deflection`` declares the bubble a record is released from (the
protocol's 1 cm): the initial state's prior mean, and, since stretch sensors cannot see a sign, the
sign of the state and so of the load. A record released from rest (flat) and analysed with that
declaration was fitted from a bubble that is not there, and the declared bubble's sign chose the
load's: FvK truth on 49x25, prestrain (0.052, 0.048), damping x1.05, 1 % noise, 1 s at 1 kHz,
uniform 180 Pa gave -1.559 ± 0.094 N for +1.764 N (not converged, warned), L1 at 443 Pa
-1.763 ± 0.055 N for +1.760 N, converged and silent.

At its release a record shows its initial shape: a stretch sensor reads ``q^T C q``, so a bubble of
peak ``a h`` reads ``a^2`` times what the declared bubble of peak ``h`` predicts. The samples of the
first :data:`START_S` (the release has barely moved the membrane: the bubble's stretch is 0.92-1.07
of its start's after 1 ms on L1, L3, LE) give ``a^2`` by least squares weighted by the noise, and
its standard deviation. The declaration is contradicted when ``a^2 = 1`` is more than
:data:`DECISIVE_SIGMA` deviations off and the record's peak is less than half or more than twice
the declared one (:data:`PEAK_FACTOR`); the fit then takes the initial shape as unknown (zero mean at
the data's scale, the sign from the prior load: :func:`~wingopt.estimation.core.start.initial_state_prior`)
and says so. Measured ``a^2`` (the truth above, 1 kHz, two samples): 0.95-1.10 on records released
from the declared bubble (L1 at 200 and 443 Pa, L2, L3, LE, uniform 180 Pa), 0.002-0.022 from rest
(the same loads, and the leading-edge tunnel load); the tunnel stand-in (its static equilibrium at
the start, 300 Hz: one sample) 0.46, its calibration (a push) 0.92: neither is refused.
"""

from __future__ import annotations

import numpy as np

from wingopt.membrane import bubble
from wingopt.membrane.forward import ModalMembrane

__all__ = ["START_S", "DECISIVE_SIGMA", "PEAK_FACTOR", "declared_start", "contradiction_note"]

START_S = 1.0e-3
"""Seconds of the record's start compared with the declared shape (the first sample and those
within this of it: two at 1 kHz, one at 300 Hz)."""

DECISIVE_SIGMA = 5.0
"""Standard deviations of ``a^2`` beyond which the record's start contradicts the declaration."""

PEAK_FACTOR = 2.0
"""How far (a factor on the peak) the record's start must be from the declared shape to be refused:
a bubble somewhat off the declared size is still the declared start, and its prior allows it."""


def declared_start(bm: ModalMembrane, problem, peak: float, t: np.ndarray, y: np.ndarray, sigma) -> dict:
    """Compare the record's first samples with the declared initial bubble of peak ``peak`` (m).

    Returns
    -------
    dict
        ``declared_m``, ``checked`` (``False`` when nothing is declared or the start has no sample),
        ``contradicted``; when checked: ``samples``, ``window_s``, ``stretch_ratio`` (``a^2``, the
        record's start over the declared bubble's) and its ``stretch_ratio_std``, ``record_peak_m``
        (``a h``; 0 when ``a^2 <= 0``) and ``sigmas`` (``|a^2 - 1|`` in standard deviations).
    """
    out = {"declared_m": float(peak), "checked": False, "contradicted": False}
    if peak == 0:
        return out
    q = bm.to_modal(bm.model.project(bubble(problem.width, problem.height, peak)))
    predicted = bm.outputs(q[None])[0]
    window = t <= t[0] + START_S * (1 + 1e-9)
    y0 = np.asarray(y, float)[window]
    w = np.where(np.isfinite(y0), 1.0, 0.0) / np.asarray(sigma, float) ** 2
    info = float(np.sum(w * predicted**2))  # Fisher information on a^2
    if not info > 0:
        return out
    ratio = float(np.sum(w * np.nan_to_num(y0) * predicted)) / info
    std = 1.0 / np.sqrt(info)
    sigmas = abs(ratio - 1.0) / std
    off = not (PEAK_FACTOR**-2 <= ratio <= PEAK_FACTOR**2)
    out.update(
        checked=True,
        contradicted=bool(sigmas > DECISIVE_SIGMA and off),
        samples=int(window.sum()),
        window_s=float(t[window][-1] - t[0]),
        stretch_ratio=ratio,
        stretch_ratio_std=float(std),
        record_peak_m=float(peak * np.sqrt(max(ratio, 0.0))),
        sigmas=float(sigmas),
    )
    return out


def contradiction_note(check: dict) -> str:
    """The warning of a record whose start contradicts the declared initial shape."""
    return (
        f"the record does not start from the declared initial shape: its first {check['samples']} sample(s) show "
        f"{check['stretch_ratio']:.1%} ± {check['stretch_ratio_std']:.1%} of the stretch that [identification] "
        f"initial_deflection = {check['declared_m']:g} m predicts (a {check['record_peak_m'] * 1000:.2g} mm bubble; "
        f"{check['sigmas']:.0f} standard deviations off): fitted with the initial shape unknown, the load's sign "
        "from initial_load"
    )
