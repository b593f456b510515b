"""Chi-square consistency of a window's residuals: where does the load model not explain the data?

The window cost is a chi-square: with the noise level right and the model adequate, the weighted
misfit of ``n`` data is ``chi2(n)`` distributed, up to a common factor ``level`` that absorbs a
misestimated noise level and a uniform model error (mesh, modal truncation: measured ``0.95 ..
1.08`` per datum on the protocol windows). A load the model cannot represent over some stretch of
the record — the load's onset when a record starts from rest, a ramp or a gust under the constant
model — shows up as *localised* excess misfit. The tests here split the residuals into segments of
``seg`` samples and flag a segment when its misfit exceeds ``level * chi2_{1 - a}(n_j)``, with
``a = significance / segments`` (Bonferroni: the family-wise false-alarm probability of one test is
at most ``significance``).

Used by the estimator (:mod:`wingopt.estimation.mhe`) in two places:

* **Onset** (:func:`leading_onset`): at the start-up, a leading run of inconsistent segments
  means the record begins with data the load model cannot explain (the flow starting, the load
  ramping up). Those samples are excluded and the start-up is redone after them, so that a first
  window the model cannot fit never becomes the arrival cost of the later ones.
* **Change** (:func:`first_inconsistent`): after each window step, the new samples are tested
  against the misfit level of the accepted start-up; an inconsistent segment means the load
  changed faster than the load model allows, and the estimator restarts there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wingopt.estimation.core.distributions import chi2_isf, chi2_median

__all__ = ["SIGNIFICANCE", "SegmentProfile", "segment_profile", "leading_onset", "first_inconsistent"]

SIGNIFICANCE = 1e-3
"""Family-wise false-alarm probability of one consistency test (all its segments together).

With about 20 tests per record (one per window step) a consistent record is flagged with
probability ~2 %; a false alarm costs a restart (information discarded), not a wrong answer."""


@dataclass(frozen=True, eq=False)
class SegmentProfile:
    """Misfit per segment of consecutive samples.

    Attributes
    ----------
    start : ndarray of int
        First sample of each segment (relative to the residual array).
    chi2, n : ndarray
        Weighted misfit and number of (non-missing) data of each segment.
    level : float
        Misfit per datum of a consistent segment (the reference).
    threshold : ndarray
        ``level * chi2_{1 - a}(n_j)``: larger misfits are inconsistent.
    samples : int
        Samples profiled.
    """

    start: np.ndarray
    chi2: np.ndarray
    n: np.ndarray
    level: float
    threshold: np.ndarray
    samples: int

    @property
    def inconsistent(self) -> np.ndarray:
        return (self.n > 0) & (self.chi2 > self.threshold)

    @property
    def per_datum(self) -> np.ndarray:
        return self.chi2 / np.maximum(self.n, 1)


def segment_profile(
    weighted_sq: np.ndarray,
    counted: np.ndarray,
    seg: int,
    level: float | None = None,
    significance: float = SIGNIFICANCE,
    leverage: np.ndarray | None = None,
    floor: float = 1.0,
) -> SegmentProfile:
    """Split residuals into segments of ``seg`` samples and set the consistency thresholds.

    Parameters
    ----------
    weighted_sq : ndarray ``(samples, p)``
        ``w (y - h)^2`` (0 where missing).
    counted : ndarray ``(samples, p)`` of bool
        Which entries are data (not missing).
    seg : int
        Samples per segment (the last segment may be shorter).
    level : float, optional
        Reference misfit per datum; default: the median over the segments of ``chi2_j / med(nu_j)``
        (``med(nu)`` the median of a chi-square with ``nu`` degrees of freedom, so that the level of
        consistent segments is 1 without bias; robust to a minority of inconsistent segments).
    significance : float
        Family-wise false-alarm probability.
    leverage : ndarray ``(samples,)``, optional
        Diagonal of the fit's hat matrix summed over the sensors of each sample. A fitted window
        absorbs part of the noise where its unknowns act (the free initial state fits the first
        samples almost exactly: misfit ~0.01 per datum there, measured), so segment ``j`` has
        ``nu_j = n_j - sum(leverage)`` degrees of freedom. Default 0 (``nu_j = n_j``: conservative).
    floor : float
        Least ``level``: consistent data misfit at least the noise, so a smaller estimated level
        (an overestimated noise level, or a short window that overfits) would only make the test
        over-sensitive (measured: 0.6-0.7 on a 60-sample start-up window at 300 Hz).
    """
    K = weighted_sq.shape[0]
    seg = max(1, int(seg))
    starts = np.arange(0, K, seg)
    chi = np.add.reduceat(weighted_sq.sum(axis=1), starts)
    n = np.add.reduceat(counted.sum(axis=1), starts).astype(float)
    nu = n if leverage is None else n - np.add.reduceat(np.asarray(leverage, dtype=float), starts)
    nu = np.maximum(nu, 0.5)
    if level is None:
        good = n > 0
        level = float(np.median(chi[good] / chi2_median(nu[good]))) if good.any() else 1.0
    level = max(float(level), floor, 1e-12)
    a = significance / max(starts.size, 1)
    thr = level * chi2_isf(a, nu)
    return SegmentProfile(starts, chi, n, level, thr, K)


def leading_onset(profile: SegmentProfile) -> int:
    """Samples to skip: the end of the leading run of inconsistent segments (0 if the first is consistent)."""
    bad = profile.inconsistent
    if not bad.size or not bad[0]:
        return 0
    if bad.all():
        return profile.samples
    return int(profile.start[int(np.argmin(bad))])


def first_inconsistent(profile: SegmentProfile) -> int | None:
    """First sample of the first inconsistent segment, or ``None`` when all are consistent."""
    bad = np.flatnonzero(profile.inconsistent)
    return None if bad.size == 0 else int(profile.start[bad[0]])
