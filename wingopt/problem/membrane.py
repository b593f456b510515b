"""The membrane-wing problem (``kind = "membrane"``): dataclasses and their TOML reader."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from wingopt.errors import InputError
from wingopt.measurements.acquisition import Acquisition
from wingopt.measurements.channels import ChannelMap
from wingopt.problem.dic import DICSettings, dic_from_table
from wingopt.problem.fields import Table
from wingopt.problem.measurements import measurements_and_acquisition

__all__ = ["MembraneMaterial", "StretchSensorSpec", "IdentificationSettings", "MembraneProblem", "from_table"]


@dataclass(frozen=True)
class MembraneMaterial:
    """Isotropic pre-strained membrane (Table 6.1)."""

    density: float = 960.0
    youngs_modulus: float = 1.3e6
    poisson_ratio: float = 0.36
    thickness: float = 1.4e-4
    prestrain: float = 0.05
    kelvin_voigt: float = 1.0e-4
    viscous: float = 5.0

    @property
    def tension(self) -> float:
        """Isotropic pre-tension ``T = E h (eps + nu eps) / (1 - nu^2)`` (eq. 4.36), N/m."""
        e, nu = self.prestrain, self.poisson_ratio
        return self.youngs_modulus * self.thickness / (1 - nu**2) * (e + nu * e)

    @property
    def areal_density(self) -> float:
        """Mass per area ``rho h``, kg/m^2."""
        return self.density * self.thickness


@dataclass(frozen=True)
class StretchSensorSpec:
    """A stretch sensor: name, rectangle ``(x0, x1, y0, y1)`` and gain ``alpha``."""

    name: str
    rect: tuple[float, float, float, float]
    gain: float = 1.0


@dataclass(frozen=True)
class IdentificationSettings:
    """Sampling and prior for load identification.

    ``initial_load`` is the uniform prior mean of the pressure (Pa); stretch sensors cannot see
    the sign of the load, so its sign decides the sign of the estimate. ``noise_std`` is the
    sensor noise standard deviation (one value, or one per sensor); ``None`` means: estimate it
    from the data. ``initial_deflection`` is the peak (m) of the prior initial shape
    ``16 xi (1 - xi) eta (1 - eta)`` (the protocol's 1 cm bubble); ``0`` means unknown. With it,
    the estimators also fix the sign of loads without net lift (L2).

    Model parameters the nonlinear estimators identify (spec §8): ``free_parameters`` (some of
    ``prestrain_x``, ``prestrain_y``, ``damping``) and their prior. Without a calibration: the
    prestrains' mean is ``[material] prestrain`` with a relative std ``prestrain_prior_rel``, the
    damping factor's mean is 1 (log-normal, std ``log(1 + damping_prior_rel)``). A calibration
    (``wingopt calibrate``) writes its posterior here: ``prestrain = [ex, ey]`` with
    ``prestrain_std = [sx, sy]`` (1-sigma) and ``prestrain_correlation`` (a ringing record fixes a
    combination of the two far better than either: correlation near -1), ``damping = d`` with
    ``damping_std`` (1-sigma of the factor), and ``calibration`` (where they came from;
    ``calibration_misfit``: the chi-square per datum of a calibration fit that did not explain its
    record, so that every run on this prior says so); they are
    then the prior.

    ``leading_edge`` (``"x0"``: the flow meets the wing at ``x = 0``; ``"x1"``: at ``x = W``; unset:
    unknown) tells the estimators of steady records which aerodynamic pressure to expect;
    ``pressure_prior`` (:data:`PRESSURE_PRIORS`) where the pressure may act.
    """

    dt: float = 1.0e-3
    initial_load: float = 200.0
    noise_std: tuple[float, ...] | None = None
    initial_deflection: float = 0.0
    free_parameters: tuple[str, ...] = ("prestrain_x", "prestrain_y", "damping")
    prestrain_prior_rel: float = 0.2
    damping_prior_rel: float = 1.0
    prestrain: tuple[float, float] | None = None
    prestrain_std: tuple[float, float] | None = None
    damping: float = 1.0
    damping_std: float | None = None
    prestrain_correlation: float = 0.0
    calibration: str = ""
    calibration_misfit: float | None = None
    leading_edge: str | None = None
    pressure_prior: str = "auto"


FREE_PARAMETERS = ("prestrain_x", "prestrain_y", "damping")
"""Names allowed in ``[identification] free_parameters``."""

PRESSURE_PRIORS = ("auto", "interior", "frame", "aerodynamic")
"""Where the pressure may act: ``interior`` (zero on the frame, the seed's loads), ``frame`` (up to
the frame: smooth interior shapes plus free-edge ones), ``aerodynamic`` (thin-airfoil shapes from
the leading edge: an assumption that narrows a steady record's band), ``auto`` (a transient record
weighs interior and frame by evidence, and its band holds the other prior's lift when the data do
not reject it: four interior sensors cannot tell whether the pressure reaches the frame; a steady
record weighs frame and aerodynamic). ``interior`` declares a load that vanishes on the frame and
keeps that prior's narrower band (L1: ±1.9 % against ±11 % under ``auto``)."""


@dataclass(frozen=True)
class MembraneProblem:
    """A rectangular membrane wing with stretch sensors, clamped (zero deflection) on all edges.

    ``dic``: the ``[dic]`` table (how DIC frames map to the wing, :mod:`wingopt.problem.dic`), if any.
    ``measurements``: the ``[measurements]`` table (a DAQ file's columns, gains and offsets,
    :mod:`wingopt.problem.measurements`), if any.
    """

    width: float
    height: float
    material: MembraneMaterial
    nodes: tuple[int, int]
    sensors: tuple[StretchSensorSpec, ...]
    identification: IdentificationSettings = IdentificationSettings()
    name: str = "membrane"
    source: str = "<memory>"
    dic: DICSettings | None = None
    measurements: ChannelMap | None = None
    acquisition: Acquisition | None = None  # [measurements] acquisition: the DAQ's filter (None: undeclared)

    kind = "membrane"

    def with_mesh(self, nodes: tuple[int, int]) -> MembraneProblem:
        """The same problem on another mesh (nodes in x, y)."""
        from wingopt.validate import check_nodes

        return dataclasses.replace(self, nodes=check_nodes(nodes))

    def with_identification(self, **fields) -> MembraneProblem:
        """The same problem with ``[identification]`` fields replaced, as a problem file would set them
        (e.g. ``pressure_prior="aerodynamic", leading_edge="x0"``)."""
        known = {f.name for f in dataclasses.fields(IdentificationSettings)}
        for name in fields:
            if name not in known:
                raise InputError(f"identification.{name}: unknown field; expected one of {', '.join(sorted(known))}")
        if "pressure_prior" in fields and fields["pressure_prior"] not in PRESSURE_PRIORS:
            raise InputError(
                f"identification.pressure_prior = {fields['pressure_prior']!r}: expected one of "
                + ", ".join(PRESSURE_PRIORS)
            )
        if "leading_edge" in fields and fields["leading_edge"] not in (None, "x0", "x1"):
            raise InputError(f"identification.leading_edge = {fields['leading_edge']!r}: expected x0, x1 or None")
        return dataclasses.replace(self, identification=dataclasses.replace(self.identification, **fields))

    def with_sensors(self, sensors) -> MembraneProblem:
        return dataclasses.replace(self, sensors=tuple(sensors))

    @property
    def sensor_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.sensors)

    def __repr__(self) -> str:
        # The dataclass repr nests every material constant and sensor rectangle (about 1000
        # characters); the fields stay reachable as attributes.
        nx, ny = self.nodes
        names = ",".join(self.sensor_names)
        names = names if len(names) <= 40 else names[:37] + "..."
        return (
            f"MembraneProblem(name={self.name!r}, {self.width:g} x {self.height:g} m, mesh {nx}x{ny}, "
            f"prestrain {self.material.prestrain:g}, {len(self.sensors)} sensors [{names}]"
            f"{', dic' if self.dic is not None else ''}, source={self.source.rsplit('/', 1)[-1]!r})"
        )


MAX_SENSORS = 1000
"""Most ``[[sensors]]`` a problem may have (each adds a sensor operator and a CSV column)."""
MAX_NAME = 100
"""Longest sensor name (it is a CSV column header and appears in messages)."""


def from_table(root: Table, name: str) -> MembraneProblem:
    """Build a :class:`MembraneProblem` from the validated top-level TOML table."""
    geo = root.table("geometry")
    width = geo.number("width", positive=True, unit="m")
    height = geo.number("height", positive=True, unit="m")
    geo.finish()

    material = _material(root)

    mesh = root.table("mesh")
    nodes = mesh.integers("nodes", 2, lo=4)
    mesh.finish()

    sensors = _sensors(root, width, height)
    names = [s.name for s in sensors]

    identification = _identification(root, len(sensors))
    dic = dic_from_table(root.table("dic")) if root.has("dic") else None
    has = root.has("measurements")
    channels, acquisition = measurements_and_acquisition(root.table("measurements"), names) if has else (None, None)
    root.finish()
    return MembraneProblem(
        width=width,
        height=height,
        material=material,
        nodes=nodes,
        sensors=tuple(sensors),
        identification=IdentificationSettings(**identification),
        name=name,
        source=root.source,
        dic=dic,
        measurements=channels,
        acquisition=acquisition,
    )


def _material(root: Table) -> MembraneMaterial:
    """The ``[material]`` table: the membrane's density, elasticity, thickness, prestrain and damping."""
    mat = root.table("material")
    material = MembraneMaterial(
        density=mat.number("density", positive=True, unit="kg/m^3"),
        youngs_modulus=mat.number("youngs_modulus", positive=True, unit="Pa"),
        poisson_ratio=mat.number("poisson_ratio", lo=-0.999, hi=0.5),
        thickness=mat.number("thickness", positive=True, unit="m"),
        # a pre-strain above 0.5 (50 %) is outside any linear membrane (the model keeps its tension constant)
        prestrain=mat.number("prestrain", lo=1e-9, hi=0.5),
        kelvin_voigt=mat.number("kelvin_voigt", 1.0e-4, nonnegative=True, unit="s"),
        viscous=mat.number("viscous", 5.0, nonnegative=True, unit="Pa s/m"),
    )
    mat.finish()
    return material


def _sensors(root: Table, width: float, height: float) -> list[StretchSensorSpec]:
    """The ``[[sensors]]`` tables: named (uniquely, not as the CSV's time column) rectangles on the wing."""
    sensors = []
    tables = root.tables("sensors", [])
    if len(tables) > MAX_SENSORS:
        raise root.error("sensors", f"{len(tables)} [[sensors]]", f"at most {MAX_SENSORS} sensors")
    for t in tables:
        sname = t.string("name")
        if sname.strip().lower() in ("t", "time") or not sname.strip() or any(c in sname for c in ',"#\n'):
            raise t.error("name", sname, "a sensor name other than 't'/'time' (the CSV time column), without , \" #")
        if not sname.isprintable() or len(sname) > MAX_NAME:
            raise t.error("name", sname, f"a sensor name of printable characters, at most {MAX_NAME} of them")
        sensors.append(
            StretchSensorSpec(
                name=sname,
                rect=t.rect("rect", width, height),
                gain=t.number("gain", 1.0, positive=True),
            )
        )
        t.finish()
    names = [s.name for s in sensors]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        raise root.error("sensors", dup, "unique sensor names")
    return sensors


def _identification(root: Table, n_sensors: int) -> dict:
    """The ``[identification]`` table's fields of :class:`IdentificationSettings` (the rig's declaration:
    sample period, sign prior and initial shape, free parameters and their priors, a calibration, noise)."""
    ident = root.table("identification", {})
    dt = ident.number("dt", 1.0e-3, positive=True, unit="s")
    initial_load = ident.number("initial_load", 200.0, unit="Pa")
    if initial_load == 0:
        raise ident.error("initial_load", initial_load, "a non-zero pressure (its sign fixes the sign of the estimate)")
    initial_deflection = ident.number("initial_deflection", 0.0, unit="m")
    free = ident.peek("free_parameters", ["prestrain_x", "prestrain_y", "damping"])
    if not isinstance(free, list) or any(not isinstance(n, str) or n not in FREE_PARAMETERS for n in free):
        raise ident.error("free_parameters", free, f"a list of names among {', '.join(FREE_PARAMETERS)}")
    ident._take("free_parameters", None, "")
    prestrain_rel = ident.number("prestrain_prior_rel", 0.2, positive=True)
    damping_rel = ident.number("damping_prior_rel", 1.0, positive=True)
    calibrated = ident.numbers("prestrain", 2, None, positive=True) if ident.has("prestrain") else None
    if calibrated is not None and max(calibrated) >= 0.5:
        raise ident.error("prestrain", list(calibrated), "two prestrains [ex, ey] below 0.5")
    calibrated_std = ident.numbers("prestrain_std", 2, None, positive=True) if ident.has("prestrain_std") else None
    if calibrated_std is not None and calibrated is None:
        raise ident.error("prestrain_std", list(calibrated_std), "a [identification] prestrain = [ex, ey] beside it")
    damping = ident.number("damping", 1.0, positive=True)
    damping_std = ident.number("damping_std", None, positive=True)
    correlation = ident.number("prestrain_correlation", 0.0, lo=-0.999, hi=0.999)
    calibration = ident.string("calibration", "")
    calibration_misfit = ident.number("calibration_misfit", None, positive=True)
    leading_edge = ident.string("leading_edge", None, choices=("x0", "x1")) if ident.has("leading_edge") else None
    pressure_prior = ident.string("pressure_prior", "auto", choices=PRESSURE_PRIORS)
    noise = None
    if ident.has("noise_std"):
        if isinstance(ident.peek("noise_std"), list):
            noise = ident.numbers("noise_std", n_sensors, positive=True)
        else:
            noise = (ident.number("noise_std", positive=True),)
    ident.finish()
    return dict(
        dt=dt,
        initial_load=initial_load,
        noise_std=noise,
        initial_deflection=initial_deflection,
        free_parameters=tuple(dict.fromkeys(free)),
        prestrain_prior_rel=prestrain_rel,
        damping_prior_rel=damping_rel,
        prestrain=None if calibrated is None else tuple(calibrated),
        prestrain_std=None if calibrated_std is None else tuple(calibrated_std),
        damping=damping,
        damping_std=damping_std,
        prestrain_correlation=correlation,
        calibration=calibration,
        calibration_misfit=calibration_misfit,
        leading_edge=leading_edge,
        pressure_prior=pressure_prior,
    )
