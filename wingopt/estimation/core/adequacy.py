"""Does the record fit the model? Chi-square per datum and per segment, the flag and the band factor.

With the noise level right and the model adequate, the weighted data misfit ``chi2`` of a fit
with ``p_eff`` effective unknowns has mean ``n - p_eff`` and std ``sqrt(2 n)``. The record is
called *inadequate* when ``chi2 / (n - p_eff)`` exceeds ``1 + tolerance`` (default 0.15: the
noise level estimated from the data is good to a few percent, so the chi-square to ~10 %) or when
a segment's misfit is improbable at ``SEGMENT_LEVEL`` after a Bonferroni correction. Then the
band is widened by ``sqrt(chi2 / (n - p_eff))`` (the misfit treated as extra noise of the same
structure, the usual scale-factor correction; by the worst misfit segment's when that is larger),
and the result carries a warning. Nothing is
dropped: segments that do not fit are *reported*, not removed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wingopt.estimation.core.distributions import chi2_sf

__all__ = ["Adequacy", "assess", "SEGMENT_LEVEL"]

SEGMENT_LEVEL = 1e-3
"""Family-wise false-alarm probability of the segment test on an adequate record."""


@dataclass(frozen=True)
class Adequacy:
    """Misfit of a fit: overall and per segment, the verdict and the band factor."""

    chi2_per_datum: float
    n_data: int
    effective_parameters: float
    segment_t: tuple[float, ...]
    segment_chi2_per_datum: tuple[float, ...]
    bad_segments: tuple[tuple[float, float], ...]
    adequate: bool
    inflation: float
    tolerance: float

    def as_dict(self) -> dict:
        return {
            "chi2_per_datum": self.chi2_per_datum,
            "n_data": self.n_data,
            "effective_parameters": self.effective_parameters,
            "segments_t_s": list(self.segment_t),
            "segments_chi2_per_datum": list(self.segment_chi2_per_datum),
            "misfit_segments_s": [list(s) for s in self.bad_segments],
            "model_adequate": self.adequate,
            "band_inflation": self.inflation,
            "tolerance": self.tolerance,
        }


def assess(
    t: np.ndarray, residuals: np.ndarray, effective_parameters: float, segment_s: float = 0.05, tolerance: float = 0.15
) -> Adequacy:
    """Judge the weighted residuals ``(N, p)`` (NaN where no sample) of a fit."""
    r = np.asarray(residuals, dtype=float)
    ok = np.isfinite(r)
    n = int(ok.sum())
    chi2 = float(np.sum(r[ok] ** 2))
    dof = max(n - effective_parameters, 1.0)
    per = chi2 / dof
    edges = np.arange(t[0], t[-1] + segment_s, segment_s)
    idx = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, max(edges.size - 2, 0))
    seg_t, seg_chi, bad = [], [], []
    nseg = int(idx.max()) + 1
    for s in range(nseg):
        rows = idx == s
        rs = r[rows][ok[rows]]
        if rs.size == 0:
            continue
        c = float(rs @ rs)
        seg_t.append(float(t[rows][0]))
        # the fit's unknowns absorb part of the noise evenly: dof share of this segment
        k = rs.size * dof / max(n, 1)
        seg_chi.append(c / max(k, 1.0))
        if chi2_sf(c, max(k, 1.0)) < SEGMENT_LEVEL / nseg:
            bad.append((float(t[rows][0]), float(t[rows][-1])))
    adequate = per <= 1.0 + tolerance and not bad
    # An adequate fit keeps its band; a misfit widens it by the worst misfit it shows (a
    # concentrated misfit, e.g. an unexplained transient, is not diluted by the good samples).
    worst = max([per] + [c for c, st in zip(seg_chi, seg_t) if any(a <= st <= b for a, b in bad)])
    inflation = 1.0 if adequate else float(np.sqrt(max(worst, 1.0)))
    return Adequacy(
        per, n, float(effective_parameters), tuple(seg_t), tuple(seg_chi), tuple(bad), adequate, inflation, tolerance
    )
