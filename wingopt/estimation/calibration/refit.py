"""When the calibration's model does not follow the record's start: the fits the data ask for, and
a band over those the data do not exclude.

A tap pushes the wing for a few ms after the record starts, and a pluck's or a tap's localized
shape rings in modes the fit's initial state leaves out: the first fit then misfits (or stops at
its iteration cap) and can settle in a wrong tension with a band from the local curvature alone
(a tap at 300 Hz: 0.0225 ± 0.0033 for 0.040). Such a record is refitted from later starts
(:data:`LATER_STARTS_S`: a tap's pulse and the first ringing left out) and, from its first sample,
with every mode's initial motion unknown. At 300 Hz the ringing aliases and the cost has several
minima: fits of the same record from different starts, each adequate, end at tensions 30 % apart.
The data do not choose between them, so the answer is the median of the adequate fits' estimates
and its band covers each of them within :data:`COVER_SD` (in quadrature with the closest fit's own
band): wide where the record does not determine the tension, said in a warning, and carried into
every run that takes the calibration as its prior (the calibration is flagged).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["COVER_SD", "LATER_STARTS_S", "Candidate", "Combined", "combine", "later_starts", "refit_warning"]

LATER_STARTS_S = (0.006, 0.012, 0.024)
"""Later starts tried (s after the record's first sample): past a tap's few-ms pulse, past the
first ringing of a localized shape; each window keeps most of the ringing."""

COVER_SD = 2.0
"""The band covers every adequate fit's estimate within this many of its stds."""

MIN_KEPT = 0.5
"""A later window keeps at least this fraction of the record's samples (and at least 20)."""

PRESTRAINS = ("prestrain_x", "prestrain_y")


@dataclass(frozen=True)
class Candidate:
    """One fit of the calibration record.

    Attributes
    ----------
    label : str
        How it was fitted (``"first"``, ``"from 13 ms"``, ``"all modes"``).
    start_s : float
        Its first sample's time after the record's first.
    parameters, parameters_std : dict
        Its posterior (misfit-inflated, model-form floor added).
    correlation : ndarray (3, 3)
    chi2_per_datum : float
    adequate, converged : bool
    payload : object
        What the caller needs to finish a calibration from it (its problem, fit and adequacy).
    """

    label: str
    start_s: float
    parameters: dict
    parameters_std: dict
    correlation: np.ndarray
    chi2_per_datum: float
    adequate: bool
    converged: bool
    payload: object

    def as_dict(self) -> dict:
        return {
            "fit": self.label,
            "start_s": self.start_s,
            "parameters": dict(self.parameters),
            "parameters_std": dict(self.parameters_std),
            "chi2_per_datum": self.chi2_per_datum,
            "adequate": self.adequate,
            "converged": self.converged,
        }


@dataclass(frozen=True)
class Combined:
    """The calibration's answer from several fits: the fit closest to the median (its damping,
    correlation and fit), the prestrains' median and their band over the adequate fits."""

    closest: Candidate
    parameters: dict
    parameters_std: dict
    correlation: np.ndarray
    widening: float
    """The largest factor the spread of the fits put on a prestrain's std."""
    used: tuple[Candidate, ...]


def later_starts(t: np.ndarray) -> list[int]:
    """Sample indices of :data:`LATER_STARTS_S` in the record ``t`` (distinct, after the first),
    each window keeping at least ``MIN_KEPT`` of the samples and 20 of them."""
    n = t.size
    last = min(n - 20, int(np.floor((1.0 - MIN_KEPT) * n)))
    out: list[int] = []
    for s in LATER_STARTS_S:
        k = int(np.searchsorted(t, t[0] + s - 1e-9))
        if 0 < k <= last and (not out or k > out[-1]):
            out.append(k)
    return out


def combine(fits: list[Candidate]) -> Combined:
    """The median of the adequate fits' prestrains (all fits' when none is adequate), the damping of
    the fit closest to it, and each prestrain's band widened in quadrature so that every used fit's
    estimate lies within :data:`COVER_SD` of it."""
    used = [f for f in fits if f.adequate] or list(fits)
    median = {n: float(np.median([f.parameters[n] for f in used])) for n in PRESTRAINS}
    spread = [max(abs(f.parameters[n] - median[n]) / max(median[n], 1e-12) for n in PRESTRAINS) for f in used]
    closest = used[int(np.argmin(spread))]
    est, std, share = dict(closest.parameters), dict(closest.parameters_std), np.ones(3)
    widening = 1.0
    for i, n in enumerate(PRESTRAINS):
        far = max(abs(f.parameters[n] - median[n]) for f in used)
        est[n] = median[n]
        std[n] = float(np.hypot(closest.parameters_std[n], far / COVER_SD))
        share[i] = closest.parameters_std[n] / std[n]
        widening = max(widening, std[n] / closest.parameters_std[n])
    # the spread of the fits is its own term: it does not share the closest fit's correlation
    corr = closest.correlation * np.outer(share, share)
    np.fill_diagonal(corr, 1.0)
    return Combined(closest, est, std, corr, float(widening), tuple(used))


def refit_warning(first: Candidate, combined: Combined, fits: list[Candidate]) -> str:
    """What the calibration says when its first fit did not hold: which fits, how far apart."""
    why = "misfits the record" if not first.adequate else "did not converge"
    lo = {n: min(f.parameters[n] for f in combined.used) for n in PRESTRAINS}
    hi = {n: max(f.parameters[n] for f in combined.used) for n in PRESTRAINS}
    spread = "; ".join(f"{n} {lo[n]:.4g}..{hi[n]:.4g}" for n in PRESTRAINS)
    return (
        f"the calibration's first fit {why} (chi-square per datum {first.chi2_per_datum:.2f}; a tap's pulse or a "
        f"localized pluck the modal model does not follow): refitted from later starts and with every mode's "
        f"initial motion unknown; {len(combined.used)} of {len(fits)} fits explain the record ({spread}): the "
        f"prestrains are their median, the band covers each (x{combined.widening:.2f})"
    )
