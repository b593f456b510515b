"""Transient records (a release, a pluck or a gust), fitted over the whole record.

* :mod:`.estimator` — :func:`transient_identify`, the fit's steps: its start, its checks and its band;
* :mod:`.run` — what one record's fits share (noise, modal model, priors, work budget);
* :mod:`.initial_shape` — does the record start from the declared initial shape?
* :mod:`.fit_result` — a fit as a result: the lift, its band and the warnings;
* :mod:`.stopping` — when the fit may stop before the solver's own test;
* :mod:`.tension_profile` — the lift's band from its profile likelihood.
"""

from wingopt.estimation.transient.estimator import transient_identify

__all__ = ["transient_identify"]
