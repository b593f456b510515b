"""The transient record fit: a release, a pluck or a gust, fitted over the whole record.

* :mod:`.estimator` — :func:`transient_identify`, the fit, its start, its checks and its band;
* :mod:`.stopping` — when the fit may stop before the solver's own test;
* :mod:`.tension_profile` — the lift's band from its profile likelihood.
"""

from wingopt.estimation.transient.estimator import transient_identify

__all__ = ["transient_identify"]
