"""The plate-wing problem (``kind = "plate"``): dataclasses and their TOML reader.

A cantilevered rectangular plate (chord ``width`` in x, span ``length`` in y, clamped along the root
``y = length``) made of a flexible skin, carbon-fibre battens (rectangles of a laminate) and
piezocomposite patch pairs (rectangles on both faces, driven with opposite voltages). See
``docs/plate.md`` for the layout of ``problems/plate.toml`` and where each value comes from.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from wingopt.errors import ProblemFileError
from wingopt.materials import plate_rigidity, reduced_stiffness
from wingopt.problem.fields import Table

__all__ = [
    "Material",
    "Laminate",
    "Piezo",
    "BattenSpec",
    "PatchSpec",
    "MorphTargets",
    "ActuatorLimits",
    "PlateProblem",
    "SHAPES",
    "from_table",
]

SHAPES = ("twist", "camber", "bending")
"""The morphing targets of Table 5.1."""

Rect = tuple[float, float, float, float]


@dataclass(frozen=True)
class Material:
    """An orthotropic layer material; direction 1 is along the fibres (isotropic: ``e1 = e2``).

    Parameters
    ----------
    density : float
        kg/m^3.
    e1, e2, g12 : float
        Young's moduli along and across the fibres and the in-plane shear modulus, Pa.
    nu12 : float
        Major Poisson ratio; the minor one is ``nu21 = nu12 e2 / e1`` (reciprocity).
    kelvin_voigt : (float, float)
        Kelvin–Voigt viscosities ``(eta1, eta2)`` along and across the fibres, Pa s (Table 5.3).
    viscous : float
        Viscous (air) damping ``gamma``, Pa s/m, per unit area of the surface (Table 5.3).
    """

    density: float
    e1: float
    e2: float
    g12: float
    nu12: float
    kelvin_voigt: tuple[float, float] = (1.0e-4, 1.0e-4)
    viscous: float = 5.0

    @classmethod
    def isotropic(cls, density: float, youngs_modulus: float, poisson_ratio: float, **kw) -> Material:
        g = youngs_modulus / (2.0 * (1.0 + poisson_ratio))
        return cls(density, youngs_modulus, youngs_modulus, g, poisson_ratio, **kw)

    @property
    def nu21(self) -> float:
        return self.nu12 * self.e2 / self.e1

    def stiffness(self) -> np.ndarray:
        """Reduced stiffness ``Q`` in material axes (eq. 4.5)."""
        return reduced_stiffness(self.e1, self.e2, self.g12, self.nu12)

    def viscosity(self) -> np.ndarray:
        """Kelvin–Voigt matrix of the structure of ``Q`` (eq. 4.6), symmetrised.

        Eq. 4.6 puts ``eta1, eta2`` where ``Q`` has ``E1, E2`` and leaves the shear entry open. Here
        the shear viscosity is ``eta12 = g12 (eta1/e1 + eta2/e2)/2`` (the mean retardation time times
        the shear modulus; ``eta/(2(1+nu))`` for an isotropic material), and the coupling is the mean
        of the two off-diagonal entries of eq. 4.6, so that the damping matrix is symmetric (only the
        symmetric part dissipates energy).
        """
        eta1, eta2 = self.kelvin_voigt
        det = 1.0 - self.nu12 * self.nu21
        off = 0.5 * (self.nu21 * eta1 + self.nu12 * eta2) / det
        eta12 = self.g12 * 0.5 * (eta1 / self.e1 + eta2 / self.e2)
        return np.array([[eta1 / det, off, 0.0], [off, eta2 / det, 0.0], [0.0, 0.0, eta12]])


@dataclass(frozen=True)
class Laminate:
    """Equal plies of one material at the given fibre angles (deg from x, bottom to top)."""

    material: Material
    thickness: float
    angles: tuple[float, ...] = (0.0,)

    @property
    def areal_density(self) -> float:
        """``rho h``, kg/m^2."""
        return self.material.density * self.thickness

    def rigidity(self) -> np.ndarray:
        """``D`` (eq. 4.11), N m."""
        return plate_rigidity(self.material.stiffness(), self.thickness, self.angles)

    def viscosity(self) -> np.ndarray:
        """Kelvin–Voigt matrix ``eta`` of the laminate (eq. 4.11), N m s."""
        return plate_rigidity(self.material.viscosity(), self.thickness, self.angles)

    def with_angles(self, angles: tuple[float, ...] | None) -> Laminate:
        return self if angles is None else dataclasses.replace(self, angles=tuple(angles))


@dataclass(frozen=True)
class Piezo:
    """Piezocomposite patch material; direction 1 along x, 2 along y. ``thickness`` is one patch.

    ``electrode_spacing`` is ``Lpz`` of eq. 4.26, the length over which the voltage acts (d33 mode:
    the pitch of the interdigitated electrodes). ``None`` takes the dissertation's literal reading,
    the patch's own length along x.
    """

    material: Material
    d33: float
    thickness: float
    electrode_spacing: float | None = None


@dataclass(frozen=True)
class BattenSpec:
    """A batten: name, rectangle ``(x0, x1, y0, y1)`` and optional ply angles (default: the file's)."""

    name: str
    rect: Rect
    angles: tuple[float, ...] | None = None


@dataclass(frozen=True)
class PatchSpec:
    """A piezocomposite patch pair (top and bottom), name and rectangle ``(x0, x1, y0, y1)``."""

    name: str
    rect: Rect


@dataclass(frozen=True)
class MorphTargets:
    """Amplitudes ``a`` (m) of the Table 5.1 shapes."""

    twist: float = 0.01
    camber: float = 0.01
    bending: float = 0.1

    def amplitude(self, shape: str) -> float:
        return getattr(self, shape)


@dataclass(frozen=True)
class ActuatorLimits:
    """Voltage limits per patch, V (a macro-fibre composite takes about -500 V … +1500 V).

    ``hysteresis`` (major-loop width, fraction of the range), ``creep`` (gain, fraction) and
    ``creep_time`` (s) describe the patches of a *simulated plant* (issue 34,
    :mod:`wingopt.control.hysteresis`); no controller model uses them. Default 0: none.
    """

    vmin: float = -500.0
    vmax: float = 1500.0
    hysteresis: float = 0.0
    creep: float = 0.0
    creep_time: float = 0.3


@dataclass(frozen=True)
class PlateProblem:
    """A cantilevered plate wing with battens and piezocomposite patch pairs.

    ``width`` is the chord (x), ``length`` the span (y); the root ``y = length`` is clamped and the
    other three edges are free. ``skin`` is the laminate where no batten is, ``batten`` the default
    laminate of the battens (a batten may override its ply angles). Patches are the inputs, in file
    order; ``piezo`` may be ``None`` only when there are none.
    """

    width: float
    length: float
    skin: Laminate
    batten: Laminate
    piezo: Piezo | None
    battens: tuple[BattenSpec, ...]
    patches: tuple[PatchSpec, ...]
    nodes: tuple[int, int]
    targets: MorphTargets = MorphTargets()
    actuators: ActuatorLimits = ActuatorLimits()
    name: str = "plate"
    source: str = "<memory>"

    kind = "plate"

    @property
    def height(self) -> float:
        """The y extent (alias of ``length``, the name the membrane problem uses)."""
        return self.length

    @property
    def patch_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.patches)

    def with_mesh(self, nodes: tuple[int, int]) -> PlateProblem:
        """The same problem on another mesh (nodes in x, y)."""
        from wingopt.validate import check_nodes

        return dataclasses.replace(self, nodes=check_nodes(nodes))

    def replace(self, **changes) -> PlateProblem:
        """A copy with fields replaced (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)

    def __repr__(self) -> str:
        # The dataclass repr nests every laminate, ply and patch (about 1700 characters); the
        # fields stay reachable as attributes.
        nx, ny = self.nodes
        act = self.actuators
        return (
            f"PlateProblem(name={self.name!r}, {self.width:g} x {self.length:g} m, mesh {nx}x{ny}, "
            f"{len(self.battens)} battens, {len(self.patches)} patches, voltage {act.vmin:g}..{act.vmax:g} V, "
            f"source={self.source.rsplit('/', 1)[-1]!r})"
        )


# -- reading ---------------------------------------------------------------------------------------


def _pair(t: Table, key: str, default: tuple[float, float]) -> tuple[float, float]:
    if isinstance(t.peek(key), list):
        a, b = t.numbers(key, 2)
        if a < 0 or b < 0:
            raise t.error(key, [a, b], "non-negative viscosities [eta1, eta2] (Pa s)")
        return (a, b)
    v = t.number(key, default[0], nonnegative=True, unit="Pa s")
    return (v, v)


def _material(t: Table, kv_default: tuple[float, float]) -> Material:
    density = t.number("density", positive=True, unit="kg/m^3")
    kv = _pair(t, "kelvin_voigt", kv_default)
    viscous = t.number("viscous", 5.0, nonnegative=True, unit="Pa s/m")
    if t.has("youngs_modulus") or t.has("poisson_ratio"):
        for key in ("e1", "e2", "g12", "nu12"):
            if t.has(key):
                raise t.error(key, t.peek(key), "either youngs_modulus/poisson_ratio (isotropic) or e1/e2/g12/nu12")
        return Material.isotropic(
            density,
            t.number("youngs_modulus", positive=True, unit="Pa"),
            t.number("poisson_ratio", lo=-0.999, hi=0.5),
            kelvin_voigt=kv,
            viscous=viscous,
        )
    e1 = t.number("e1", positive=True, unit="Pa")
    e2 = t.number("e2", positive=True, unit="Pa")
    g12 = t.number("g12", positive=True, unit="Pa")
    nu12 = t.number("nu12", lo=-0.999, hi=0.999)
    if 1.0 - nu12 * nu12 * e2 / e1 <= 0:
        raise t.error("nu12", nu12, f"1 - nu12^2 e2/e1 > 0 (a stable ply); got {1.0 - nu12 * nu12 * e2 / e1:.3g}")
    return Material(density, e1, e2, g12, nu12, kelvin_voigt=kv, viscous=viscous)


def _angles(t: Table, key: str, default) -> tuple[float, ...] | None:
    if not t.has(key):
        return None if default is None else tuple(default)
    val = t.numbers(key, None)
    if any(abs(a) > 180.0 for a in val):
        raise t.error(key, list(val), "fibre angles in degrees within [-180, 180]")
    return tuple(val)


def _laminate(t: Table, kv_default, angles_default) -> Laminate:
    material = _material(t, kv_default)
    thickness = t.number("thickness", positive=True, unit="m")
    angles = _angles(t, "plies", angles_default)
    t.finish()
    return Laminate(material, thickness, angles)


def _unique(root: Table, key: str, names: list[str]) -> None:
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        raise root.error(key, dup, f"unique {key} names")


def _overlap(a: Rect, b: Rect) -> bool:
    return a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3]


def from_table(root: Table, name: str) -> PlateProblem:
    """Build a :class:`PlateProblem` from the validated top-level TOML table."""
    geo = root.table("geometry")
    width = geo.number("width", positive=True, unit="m")
    length = geo.number("length", positive=True, unit="m")
    geo.finish()

    mats = root.table("materials")
    skin = _laminate(mats.table("plate"), (1.0e-4, 1.0e-4), (0.0,))
    # Batten and piezo materials are needed only by a plate that has battens / patches: without them
    # the skin stands in (never used: no rectangle refers to it).
    if mats.has("batten") or root.peek("battens"):
        batten = _laminate(mats.table("batten"), (1.0e-4, 1.0e-4), (90.0, 90.0, 90.0, 90.0))
    else:
        batten = skin
    if mats.has("piezo") or root.peek("patches"):
        pt = mats.table("piezo")
        pmat = _material(pt, (5.0e-5, 5.0e-5))
        d33 = pt.number("d33", positive=True, unit="m/V")
        pthick = pt.number("thickness", positive=True, unit="m")
        spacing = pt.number("electrode_spacing", None, positive=True, unit="m")
        pt.finish()
        piezo = Piezo(pmat, d33, pthick, spacing)
    else:
        piezo = Piezo(skin.material, 1.0e-12, skin.thickness, None)
    mats.finish()

    battens = []
    for t in root.tables("battens", []):
        battens.append(BattenSpec(t.string("name"), t.rect("rect", width, length), _angles(t, "plies", None)))
        t.finish()
    _unique(root, "battens", [b.name for b in battens])

    patches = []
    for t in root.tables("patches", []):
        patches.append(PatchSpec(t.string("name"), t.rect("rect", width, length)))
        t.finish()
    _unique(root, "patches", [p.name for p in patches])
    for i, a in enumerate(patches):
        for b in patches[i + 1 :]:
            if _overlap(a.rect, b.rect):
                raise ProblemFileError(
                    f"{root.source}: [[patches]] {a.name} {list(a.rect)} and {b.name} {list(b.rect)} overlap: "
                    "expected disjoint patches (one pair per place)"
                )

    mesh = root.table("mesh")
    nodes = mesh.integers("nodes", 2, lo=4)
    mesh.finish()

    tg = root.table("targets", {})
    targets = MorphTargets(**{s: tg.number(s, getattr(MorphTargets, s), unit="m") for s in SHAPES})
    tg.finish()

    act = root.table("actuators", {})
    vmin = act.number("vmin", ActuatorLimits.vmin, unit="V")
    vmax = act.number("vmax", ActuatorLimits.vmax, unit="V")
    if not vmin < vmax:
        raise act.error("vmax", vmax, f"a voltage above vmin = {vmin!r}")
    hysteresis = act.number("hysteresis", 0.0, lo=0.0, hi=0.3)  # the plant's patches (issue 34)
    creep = act.number("creep", 0.0, lo=0.0, hi=1.0)
    creep_time = act.number("creep_time", 0.3, positive=True, unit="s")
    act.finish()
    root.finish()
    return PlateProblem(
        width=width,
        length=length,
        skin=skin,
        batten=batten,
        piezo=piezo,
        battens=tuple(battens),
        patches=tuple(patches),
        nodes=nodes,
        targets=targets,
        actuators=ActuatorLimits(vmin, vmax, hysteresis, creep, creep_time),
        name=name,
        source=root.source,
    )
