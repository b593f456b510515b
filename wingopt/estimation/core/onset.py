"""Where a transient record's motion starts: a lab's pre-trigger, found and left out of the fit.

A DAQ triggered by the release (or by a pluck, a tap, the flow's start) keeps a pre-trigger: samples
of the wing holding still before it moves. The transient and calibration fits start the motion at
the record's first sample, so a record that holds still for 0.1 s first reads as a wing that does
not move when it should (measured: L1 released from the bubble, FvK truth, 300 Hz, 0.1 s of
pre-trigger: +98 % ± 73 N, chi-square 75, "cannot identify this record"; without it -2.6 %).

:func:`quiet_lead` finds the samples at the start that hold still before an abrupt start: each
within :data:`LEVEL` noise std of the mean of the samples before it, until two in a row are not and
the motion reaches :data:`JUMP` std within :data:`RISE` samples (a release or a pluck rings at once;
a gust or a drift departs gradually and is the fit's to model, and a record that moves from its
first samples has no lead). The fit then starts at the last still sample: the wing's state before
the motion, which the fit's initial-state prior states (the declared shape held, or rest). The
samples left out are the pre-trigger's, the same state over again; the run says how many.
"""

from __future__ import annotations

import numpy as np

__all__ = ["quiet_lead", "lead_note", "LEVEL", "JUMP", "RISE", "MIN_LEAD", "MIN_LEAD_S"]

LEVEL = 5.0
"""Noise std from the still samples' mean at which a sample has moved."""

JUMP = 20.0
"""Noise std the motion reaches within :data:`RISE` samples of its start when the start is abrupt."""

RISE = 3
"""Samples after the first moved one within which an abrupt start reaches :data:`JUMP`."""

MIN_LEAD = 5
"""Still samples at least for a lead to be left out (fewer are within a trigger's own jitter)."""

MIN_LEAD_S = 0.02
"""Still time at least (s) for a lead to be left out: a pre-trigger is tens of milliseconds or more,
where a wing loaded from rest may show nothing above a 5 % noise for a few milliseconds (its
stretch grows with the square of a deflection that grows with the square of time) while it moves."""


def quiet_lead(y: np.ndarray, sigma: np.ndarray, dt: float, acquisition=None) -> int:
    """The number of still samples at the start of the record ``y`` before an abrupt start.

    Parameters
    ----------
    y : ndarray ``(N, p)``
        The record (NaN where a sample is missing).
    sigma : ndarray ``(p,)``
        The sensors' noise std.
    dt : float
        The sample period (s).
    acquisition : Acquisition, optional
        The declared DAQ: the still samples its declared delay (``delay_s``) puts before the motion
        are the record's, which the fit's prediction models (it is shifted by the delay); they stay.

    Returns
    -------
    int
        Samples to leave out: the fit starts at sample ``lead`` (the last still one); 0 when the
        record moves from its first samples, holds still throughout, or departs gradually.
    """
    z = np.asarray(y, float) / np.asarray(sigma, float)
    start = _first_move(z)
    if start is None or start < MIN_LEAD + 1 or (start - 1) * dt < MIN_LEAD_S:
        return 0
    rise = np.abs(z[start : start + RISE + 1] - _still_mean(z[:start]))
    if not np.nanmax(rise, initial=0.0) >= JUMP:
        return 0
    delay = getattr(acquisition, "delay_s", None) or 0.0
    lead = start - 1 - int(np.ceil(delay / dt - 1e-9))
    return lead if lead >= MIN_LEAD and lead * dt >= MIN_LEAD_S else 0


def _first_move(z: np.ndarray) -> int | None:
    """The first of two samples in a row more than :data:`LEVEL` from the mean of the still ones before
    them (a moved sample alone, a glitch, is left out of that mean and forgotten)."""
    total, count = np.zeros(z.shape[1]), np.zeros(z.shape[1])
    moved_at = -2
    for k, row in enumerate(z):
        ok = np.isfinite(row) & (count > 0)
        if ok.any() and np.max(np.abs(row[ok] - total[ok] / count[ok])) > LEVEL:
            if moved_at == k - 1:
                return k - 1
            moved_at = k
            continue
        seen = np.isfinite(row)
        total[seen] += row[seen]
        count[seen] += 1
    return None


def _still_mean(z: np.ndarray) -> np.ndarray:
    """The still samples' level: their median (a glitch among them does not move it)."""
    return np.nanmedian(z, axis=0)


def lead_note(lead: int, t: np.ndarray) -> str:
    """What a run says of the ``lead`` samples it left out (``t``: the times the fit starts from)."""
    dt = float(t[1] - t[0])
    return (
        f"the record holds still for its first {lead} samples ({lead * dt:.3g} s: a pre-trigger) before an abrupt "
        f"start; the fit starts at its last still sample (t = {float(t[0]):.4g} s), the state its initial prior "
        "states, and leaves the still samples before it out"
    )
