"""Modal membranes (the estimators' models): linear, Berger and cubic FvK on the lowest modes.

:class:`ModalMembrane` holds the modes and the linear part; :class:`BergerModal` and
:class:`FvKModal` add the deflection's own stiffening, integrated by the exact-oscillator
predictor-corrector (:mod:`.oscillator`) with exact tangents (:mod:`.tangent`, :mod:`.kernels`)
and one-sample maps for the streaming filter (:mod:`.berger_step`, :mod:`.fvk_step`).
"""

from wingopt.membrane.modal.base import ModalMembrane
from wingopt.membrane.modal.berger import BergerModal
from wingopt.membrane.modal.fvk import FvKModal

__all__ = ["ModalMembrane", "BergerModal", "FvKModal"]
