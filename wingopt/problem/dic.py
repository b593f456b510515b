"""A membrane problem's ``[dic]`` table: how the DIC system's coordinates and files map to the wing.

::

    [dic]
    origin = [-70.0, 35.0]     # DIC position of the wing's origin (leading edge at the root), DIC units
    x_axis = "+x"              # the DIC axis (with its sign) along the wing's chord x
    y_axis = "-y"              # ... along the span y
    z_axis = "+z"              # the DIC Z's sign along the deflection w
    unit = "mm"                # DIC length unit: "m" or "mm"
    strain_unit = "strain"     # "strain" (dimensionless) or "percent"
    frame_rate = 300.0         # Hz: per-frame files (DICe, CSV) carry no time
    strain_reference = "prestrained"   # the reference image: the mounted membrane ("unstrained": before mounting)
    strain_kind = "inplane"    # optional: "surface" (VIC-3D's Lagrange strain), "inplane" (DICe's VSG), "none"

Every key is optional; a bad value is one line naming it. The NPZ layout is in the wing's frame
already (:mod:`wingopt.measurements.dic`): it takes none of the mapping keys.
"""

from __future__ import annotations

from dataclasses import dataclass

from wingopt.measurements.dic import AXES, STRAIN_KINDS, STRAIN_REFERENCES, STRAIN_UNITS, UNITS, DICMapping
from wingopt.problem.fields import Table

__all__ = ["DICSettings", "dic_from_table"]


@dataclass(frozen=True)
class DICSettings:
    """The ``[dic]`` table (module docstring): the coordinate mapping and how to read the frames."""

    mapping: DICMapping = DICMapping()
    frame_rate: float | None = None
    strain_reference: str = "prestrained"
    strain_kind: str | None = None


def dic_from_table(t: Table) -> DICSettings:
    """Validate a ``[dic]`` table (every key optional; unknown keys refused)."""
    origin = t.numbers("origin", 2, [0.0, 0.0])
    axes = {}
    for key, allowed in (("x_axis", tuple(AXES)), ("y_axis", tuple(AXES)), ("z_axis", ("+z", "-z"))):
        axes[key] = t.string(key, "+" + key[0], choices=allowed)
    if axes["x_axis"][1] == axes["y_axis"][1]:
        raise t.error("y_axis", axes["y_axis"], f"a DIC axis other than x_axis = {axes['x_axis']!r}")
    unit = t.string("unit", "m", choices=tuple(UNITS))
    strain_unit = t.string("strain_unit", "strain", choices=tuple(STRAIN_UNITS))
    rate = t.number("frame_rate", None, positive=True, unit="Hz")
    reference = t.string("strain_reference", "prestrained", choices=STRAIN_REFERENCES)
    kind = t.string("strain_kind", None, choices=STRAIN_KINDS) if t.has("strain_kind") else None
    t.finish()
    mapping = DICMapping(tuple(origin), unit=unit, strain_unit=strain_unit, **axes)
    return DICSettings(mapping, rate, reference, kind)
