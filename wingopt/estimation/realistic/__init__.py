"""Load identification on real membranes (issue 11, spec §8).

* :mod:`.berger_modal` — the fast nonlinear (Berger-type) membrane in modal coordinates;
* :mod:`.tangent` — its exact forward sensitivities;
* :mod:`.fvk_model` — the cubic modal Föppl–von Kármán membrane (``membrane_model="fvk"``), same interface;
* :mod:`.load_model` — smooth load shapes with a gust-following amplitude;
* :mod:`.record_problem`, :mod:`.solver` — the record's chi-square and Levenberg–Marquardt;
* :mod:`.adequacy` — chi-square per datum and per segment, the flag and the band factor;
* :mod:`.estimator` — :func:`realistic_identify`, the whole estimator;
* :mod:`.mhe_check` — the same adequacy check added to the linear MHE's result;
* :mod:`.truth` — Berger truth records (finer mesh, more modes) for tests and studies.
"""

from wingopt.estimation.realistic.estimator import LOAD_MODELS, MEMBRANE_MODELS, RealisticSettings, realistic_identify

__all__ = ["RealisticSettings", "realistic_identify", "LOAD_MODELS", "MEMBRANE_MODELS"]
