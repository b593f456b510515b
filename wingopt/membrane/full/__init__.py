"""Full-order membranes (every spline coefficient a degree of freedom): the truth generators' models.

:class:`BergerMembrane` (uniform tension) and :class:`FvKMembrane` (Föppl–von Kármán, in-plane
equilibrium solved), both integrated by :func:`integrate` (exponential-trapezoidal).
"""

from wingopt.membrane.full.berger import BergerMembrane
from wingopt.membrane.full.fvk import FvKMembrane, StaticSolution
from wingopt.membrane.full.integrator import FullRecord, integrate

__all__ = ["BergerMembrane", "FvKMembrane", "StaticSolution", "FullRecord", "integrate"]
