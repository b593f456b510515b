"""The steady record fit: a loaded wing in steady flow (a wind tunnel), no transient.

* :mod:`.problem` — the mean's static fit;
* :mod:`.spectra`, :mod:`.buffeting`, :mod:`.buffeting_fit` — the tension from the buffeting's spectrum;
* :mod:`.anti_aliasing` — a DAQ filter found near Nyquist;
* :mod:`.solutions` — the solutions under one load prior;
* :mod:`.wiring` — a sensor's gain, offset or a swap, against the static fit of the means (the
  transient fit runs it too);
* :mod:`.estimator` — :func:`steady_identify`, :func:`is_steady` and the steady route's own checks.
"""

from wingopt.estimation.steady.estimator import is_steady, steady_identify

__all__ = ["is_steady", "steady_identify"]
