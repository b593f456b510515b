"""The transient stream's batch check: the whole-record fit of its first look, carried into its band.

A filter's band is its prior's: the load shapes it streams (the interior prior) and the
linearisation at its own path. The batch route weighs the frame prior against the interior one
(:mod:`wingopt.estimation.core.frame_check`) and widens its band by the lift the two priors
give (``info["frame_check"]["lift_spread"]``); the stream did not (L3 on FvK truth: the stream
ended 6.8 of its bands off). At the first look that finds a stream transient
(:class:`~.steady_refit.SteadyRefit`) the record so far is fitted once by the batch route, and:

* the lift its load priors leave open (the frame check's spread, and the prior check's when the
  load is outside the interior prior: the batch band's prior terms) is added to the stream's band
  from then on, with a warning, and the stream's band is never narrower than the batch's (the
  filter summarises the same samples in a Gaussian arrival cost: it cannot know more; L3, FvK
  truth 49x25: the filter 0.713 ± 0.011 N, the batch 0.758 ± 0.061 N, the truth 0.794 N);
* a filter whose lift is more than :data:`AGREE_BANDS` combined bands from the batch fit's is
  flagged (its estimates inadequate) and said, with the batch's answer in ``info``: a filter that
  went on from a poor start (measured: L2 without a declared initial shape, +37 of its bands)
  no longer ends confident and silent;
* what the batch fit says about its answer (its warnings: a frame prior it cannot tell from the
  interior one, a stalled fit, ...) is said by the stream too, and a batch fit that misfits the
  samples (status ``misfit``: the same model does not explain them) flags the stream's answer: the
  filter agreeing with such a fit confirms nothing (fuzz record #109, FvK truth, a leading-edge
  tunnel load: the filter 1.145 ± 0.085 N, the batch 1.163 ± 0.085 N with a warning that the
  sensors do not tell whether the load reaches the frame, the truth 1.475 N; the stream said
  nothing).

The check costs one batch fit of the first look's record (about a second of data), once.
"""

from __future__ import annotations

import dataclasses
import logging
import math

from wingopt.estimation.core.result import Estimate, IdentificationResult

__all__ = ["BatchCheck", "AGREE_BANDS", "MAX_CHECK_SAMPLES"]

log = logging.getLogger(__name__)

AGREE_BANDS = 2.0
"""Combined bands (filter and batch, in quadrature) within which the two lifts agree."""

MAX_CHECK_SAMPLES = 20_000
"""The longest record the check fits (a stream found transient after a long steady run is not)."""


@dataclasses.dataclass
class BatchCheck:
    """The batch fit's lift and band, its frame check's spread and the filter's gap to it."""

    t_s: float
    samples: int
    lift: float
    lift_std: float
    spread: float
    gap_bands: float
    filter_lift: float
    filter_std: float
    error: str | None = None
    status: str = ""
    notes: tuple[str, ...] = ()

    @classmethod
    def of(cls, result: IdentificationResult, last: Estimate, samples: int) -> BatchCheck:
        lift, std = result.reported_lift
        std = 0.0 if std is None or not math.isfinite(std) else float(std)
        info = result.info
        # the batch band's prior terms: the frame prior's lift and the wider load priors' (:mod:`.prior_check`)
        frame = float((info.get("frame_check") or {}).get("lift_spread") or 0.0)
        prior = float((info.get("load_prior") or {}).get("lift_spread") or 0.0)
        spread = math.hypot(frame, prior)
        band = math.hypot(last.lift_std, math.hypot(std, spread)) if math.isfinite(last.lift_std) else math.inf
        gap = abs(last.lift - lift) / band if band > 0 and math.isfinite(last.lift) else math.inf
        notes = tuple(str(w) for w in info.get("warnings", ()))
        filt = (float(last.lift), float(last.lift_std))
        status = str(getattr(result, "status", ""))  # an IdentificationResult; a bare answer has none
        return cls(float(last.t), samples, float(lift), std, spread, float(gap), *filt, status=status, notes=notes)

    @classmethod
    def failed(cls, last: Estimate, samples: int, exc: BaseException) -> BatchCheck:
        nan = float("nan")
        filt = (float(last.lift), float(last.lift_std))
        return cls(float(last.t), samples, nan, nan, 0.0, 0.0, *filt, error=f"{type(exc).__name__}: {exc}")

    @property
    def agrees(self) -> bool:
        return self.error is not None or self.gap_bands <= AGREE_BANDS

    @property
    def fits(self) -> bool:
        """The batch fit explains the samples (its status is not ``misfit``)."""
        return self.status != "misfit"

    def widened(self, e: Estimate) -> Estimate:
        """``e`` with the spread in its band, at least the batch's band, flagged when the filter
        disagrees with the batch."""
        std = math.hypot(e.lift_std, self.spread) if math.isfinite(e.lift_std) else e.lift_std
        if self.error is None and math.isfinite(self.lift_std):
            std = max(std, self.lift_std)  # the same samples' whole posterior: the filter cannot know more
        return dataclasses.replace(e, lift_std=std, adequate=bool(e.adequate and self.agrees and self.fits))

    def warnings(self) -> list[str]:
        if self.error is not None:
            return [f"the whole-record batch check of the stream's first {self.samples} samples failed ({self.error})"]
        out = []
        if self.spread > 0:
            out.append(
                f"the lift depends on the load prior by {self.spread:.4g} N (the frame and wider load priors of the "
                f"whole-record batch fit of the first {self.samples} samples): added to the stream's band"
            )
        if not self.agrees:
            out.append(
                f"the filter's lift ({self.filter_lift:.4g} ± {self.filter_std:.2g} N at t = {self.t_s:.3g} s) "
                f"is {self.gap_bands:.1f} bands from the whole-record batch fit's ({self.lift:.4g} ± "
                f"{self.lift_std:.2g} N) of the same samples: the filter's answer is flagged; run the batch identify "
                "on the stored record"
            )
        if not self.fits:
            out.append(
                f"the whole-record batch fit of the first {self.samples} samples misfits them (status misfit): the "
                "filter's model does not explain them either, and its answer is flagged"
            )
        out += [f"the whole-record batch fit of the first {self.samples} samples says: {w}" for w in self.notes]
        return out

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)
