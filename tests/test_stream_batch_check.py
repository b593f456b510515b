"""The transient stream's batch check says what the batch fit says about its answer, and a batch fit
that misfits the samples flags the filter that agrees with it (issue 32, fuzz record #109: the stream
1.145 ± 0.085 N for 1.475 N, silent, where the batch fit of the same samples warned)."""

from types import SimpleNamespace

from wingopt.estimation.core.result import Estimate
from wingopt.estimation.streaming.batch_check import BatchCheck

FRAME = "the sensors do not tell whether the pressure reaches the frame: the lift and its band mix the two"


def _estimate() -> Estimate:
    return Estimate(999, 0.999, 0.71, 0.01, None, 1.0, True, "tracking")


def test_the_batch_fits_warnings_are_the_streams_too():
    batch = SimpleNamespace(reported_lift=(0.72, 0.05), info={"warnings": [FRAME]}, status="converged")
    check = BatchCheck.of(batch, _estimate(), 1000)
    assert check.fits and check.widened(_estimate()).adequate
    assert check.warnings() == [f"the whole-record batch fit of the first 1000 samples says: {FRAME}"]


def test_a_batch_fit_that_misfits_flags_the_filter_that_agrees_with_it():
    batch = SimpleNamespace(reported_lift=(0.72, 0.05), info={}, status="misfit")
    check = BatchCheck.of(batch, _estimate(), 1000)
    assert check.agrees and not check.fits
    assert not check.widened(_estimate()).adequate
    assert any("misfits them" in w and "flagged" in w for w in check.warnings())
