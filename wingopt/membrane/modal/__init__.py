"""Modal membranes (the estimators' models): linear, Berger and cubic FvK on the lowest modes.

:class:`ModalMembrane` holds the modes and the linear part; :class:`BergerModal` and
:class:`FvKModal` add the deflection's own stiffening, each as a force law (:mod:`.laws`) of the
one compiled loop (:mod:`.kernels`: exact oscillators in a predictor-corrector; the record, its
exact tangent and the streaming filter's one-sample map, :class:`~.sample.ModalSample`).
Estimators build them through :func:`wingopt.membrane.forward.modal_model` (cached).
"""

from wingopt.membrane.modal.base import ModalMembrane
from wingopt.membrane.modal.berger import BergerModal
from wingopt.membrane.modal.fvk import FvKModal

__all__ = ["ModalMembrane", "BergerModal", "FvKModal"]
