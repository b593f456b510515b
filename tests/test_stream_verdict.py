"""The stream's verdict on its whole record (:mod:`wingopt.estimation.streaming.verdict`): a filter
that went on from a batch fit that misfits, or whose windows misfit through much of the record, is
flagged to its end (issue 32, fuzz record #21: `converged` 4.7 bands off after a gust)."""

from wingopt.estimation.streaming.verdict import MISFIT_FRACTION, Verdict


def test_a_record_that_fits_is_not_flagged():
    v = Verdict(0.15)
    v.fitted(1.1, 300, "start-up")
    for _ in range(1000):
        v.sample(True)
    v.sample(False)  # one misfit window: the test's false alarm
    assert v.ok and v.warnings() == [] and v.as_dict()["misfit_samples"] == 1


def test_a_start_up_fit_that_misfits_flags_the_record_for_good():
    v = Verdict(0.15)
    v.fitted(15.9, 150, "reset")
    for _ in range(1000):
        v.sample(True)
    assert not v.ok
    (said,) = v.warnings()
    assert "reset" in said and "15.9" in said and "flagged" in said


def test_windows_that_misfit_through_a_tenth_of_the_record_flag_it_while_they_do():
    v = Verdict(0.15)
    for k in range(100):
        v.sample(k % 5 != 0)  # a fifth of the windows misfit
    assert not v.ok and "20%" in v.warnings()[0]
    for _ in range(200):  # a long stream that fits again: what it could not follow weighs little now
        v.sample(True)
    assert v.misfit_share <= MISFIT_FRACTION and v.ok
