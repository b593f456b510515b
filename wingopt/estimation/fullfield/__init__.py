"""The full-field (DIC) estimator: the membrane's pressure from its measured shape (issue 24).

* :mod:`.settings` — :class:`FullFieldSettings`;
* :mod:`.data` — frame fits, the mean field and its noise, the in-plane check;
* :mod:`.system` — pressure from shape: the linearised FvK balance of a measured deflection;
* :mod:`.steady` — the steady fit under each load prior, the prestrains' part of the band;
* :mod:`.frames` — the time-resolved mode (inertia included);
* :mod:`.estimator` — :func:`fullfield_identify`, the whole estimator.
"""

from wingopt.estimation.fullfield.estimator import fullfield_identify
from wingopt.estimation.fullfield.settings import FullFieldSettings

__all__ = ["FullFieldSettings", "fullfield_identify"]
