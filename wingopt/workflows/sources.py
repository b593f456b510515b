"""What an identification reads: a simulated case, a measured record or DIC frames.

``identify`` takes one data source. Each source validates its own options and turns itself into a
:class:`SourceRecord` (the measurements, and what the source knows beside them: the truth of a
simulated case, the DIC frames, the data report for ``summary.json``). The options that only make
sense for a simulation (noise, seed, truth physics and mesh, duration, gust) exist only on
:class:`SimulatedCase`: given with measured data or frames they are refused in one line
(:func:`data_source`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.core import sanity
from wingopt.estimation.options import IdentifyOptions
from wingopt.measurements import ChannelMap, Measurements, read_measurements
from wingopt.measurements.dic import DICFrames
from wingopt.membrane import TruthRecord
from wingopt.membrane.loads import LOAD_CASES
from wingopt.validate import check_nodes, check_number, check_seed
from wingopt.values import NoiseLevel
from wingopt.workflows.dic import dic_record
from wingopt.workflows.protocols import TRUTH_NODES, check_truth_settings, simulate_case
from wingopt.workflows.studies import protocol_sign

__all__ = ["SimulatedCase", "MeasuredRecord", "DICRecord", "SourceRecord", "data_source", "SIMULATION_ONLY"]

SIMULATION_ONLY = {
    "noise_percent": "--noise",
    "seed": "--seed",
    "truth": "--truth",
    "truth_nodes": "--truth-mesh",
    "truth_prestrain": "--truth-prestrain",
    "truth_damping": "--truth-damping",
    "t_end": "--t-end",
    "gust": "--gust",
}
"""The options of a simulated case (API name -> command-line flag): nothing else has them."""


@dataclass(frozen=True)
class SourceRecord:
    """A source read for one estimator: its measurements and what the source knows beside them."""

    problem: Any
    measurements: Measurements
    case: TruthRecord | None = None
    frames: DICFrames | None = None
    report: dict | None = None
    protocol: dict = field(default_factory=dict)
    options: IdentifyOptions | None = None
    """The options with what the source decides (a simulated case's sign prior)."""


def _with_noise_std(meas: Measurements, std: float | None) -> Measurements:
    if std is None:
        return dataclasses.replace(meas, noise_std=None)
    return dataclasses.replace(meas, noise_std=np.full(len(meas.sensor_names), float(std)))


@dataclass(frozen=True)
class SimulatedCase:
    """The simulated protocol: ``load`` on a truth membrane (full order, ``truth_nodes`` mesh).

    ``noise_percent`` is in percent of each sensor's peak output; ``truth_prestrain`` ``(ex, ey)``,
    ``truth_damping`` (a factor) and ``gust`` (a :class:`~wingopt.membrane.Gust`) put the truth off
    the problem file; ``truth_nodes=None`` is the seed's same-mesh protocol.
    """

    load: str
    noise_percent: float = 1.0
    seed: int = 0
    truth: str = "linear"
    truth_nodes: tuple[int, int] | None = TRUTH_NODES
    truth_prestrain: tuple[float, float] | None = None
    truth_damping: float = 1.0
    t_end: float = 1.0
    gust: Any = None

    def __post_init__(self) -> None:
        if not isinstance(self.load, str) or self.load not in LOAD_CASES:
            raise InputError(f"load = {self.load!r}: expected one of {', '.join(LOAD_CASES)}")
        check_seed(self.seed)
        check_truth_settings(self.truth, self.truth_prestrain, self.truth_damping)
        check_number("t_end", self.t_end, positive=True)
        check_number("noise_percent", self.noise_percent, lo=0.0, hi=100.0)
        if self.truth_nodes is not None:
            object.__setattr__(self, "truth_nodes", check_nodes(self.truth_nodes, "truth_nodes"))
        if self.gust is not None and not callable(getattr(self.gust, "factor", None)):
            raise InputError(f"gust = {self.gust!r}: expected a wingopt.membrane.Gust or None")

    def samples(self, problem) -> int:
        sanity.check_duration(self.t_end, problem.identification.dt)
        return int(round(self.t_end / problem.identification.dt)) + 1

    def describe(self, problem) -> dict:
        off_file = (
            self.truth != "linear" or self.truth_prestrain is not None or self.truth_damping != 1.0
        ) or self.gust is not None
        truth = self.truth
        if off_file:
            truth += f" (prestrain {self.truth_prestrain}, damping x{self.truth_damping:g}"
            truth += ", gust)" if self.gust is not None else ")"
        return {
            "load_case": self.load,
            "noise_percent": float(self.noise_percent),
            "seed": self.seed,
            "truth_mesh": list(self.truth_nodes or problem.nodes),
            "protocol": "same-mesh (seed)" if self.truth_nodes is None else "fine-mesh truth",
            "truth": truth,
        }

    def read(self, problem, options: IdentifyOptions) -> SourceRecord:
        fraction = NoiseLevel.from_percent(self.noise_percent).fraction
        case = simulate_case(
            problem,
            self.load,
            fraction,
            self.seed,
            self.truth_nodes,
            self.t_end,
            truth=self.truth,
            prestrain=self.truth_prestrain,
            damping=self.truth_damping,
            gust=self.gust,
            tell_noise=False,
        )
        if options.initial_load is None:  # the protocol states the sign, as a lab would
            options = options.replace(initial_load=protocol_sign(self.load) * abs(problem.identification.initial_load))
        meas = _with_noise_std(case.measurements, options.noise_std)
        protocol = self.describe(problem)
        protocol["noise_percent"] = 100 * fraction
        return SourceRecord(problem, meas, case=case, protocol=protocol, options=options)


@dataclass(frozen=True)
class MeasuredRecord:
    """A measured record: a CSV file (``channels``: a DAQ's columns, gains and offsets, default the
    problem's ``[measurements]``), a :class:`Measurements`, or an array of rows ``t, s_1 .. s_p``."""

    data: Any
    channels: ChannelMap | None = None

    def read(self, problem, options: IdentifyOptions) -> SourceRecord:
        if isinstance(self.data, (str, Path)):  # read_measurements refuses a directory (one line naming data)
            meas, report = read_measurements(self.data, problem.sensor_names, self.channels or problem.measurements)
            return SourceRecord(
                problem, _with_noise_std(meas, options.noise_std), report=report.as_dict(), options=options
            )
        if self.channels is not None:
            raise InputError("channels: apply to a CSV file given as data (a path), not to arrays or Measurements")
        meas = sanity.as_measurements(self.data, problem.sensor_names)
        return SourceRecord(problem, _with_noise_std(meas, options.noise_std), options=options)


@dataclass(frozen=True)
class DICRecord:
    """DIC frames (a directory, an ``.npz`` file or :class:`DICFrames`), mapped by the problem's ``[dic]``.

    ``full_field``: the frames are the data (the full-field estimator); otherwise their virtual
    stretch sensors are, with the first frame's shape as the initial deflection."""

    frames: Any

    def read(self, problem, options: IdentifyOptions, full_field: bool = True) -> SourceRecord:
        problem, frames, meas, report = dic_record(problem, self.frames, full_field)
        meas = meas if options.noise_std is None else _with_noise_std(meas, options.noise_std)
        return SourceRecord(problem, meas, frames=frames, report=report, options=options)


Source = SimulatedCase | MeasuredRecord | DICRecord


def data_source(
    *, load=None, data=None, dic=None, channels: ChannelMap | None = None, **simulated
) -> SimulatedCase | MeasuredRecord | DICRecord:
    """The one source of ``load`` (simulated), ``data`` (measured) or ``dic`` (frames).

    ``simulated`` holds the simulation-only options given (:data:`SIMULATION_ONLY`; ``None`` is
    not given, except ``truth_nodes=None``: the same-mesh protocol). Exactly one source must be
    given; simulation-only options with measured data or frames, and ``channels`` with anything but
    measured data, are refused in one line naming them.
    """
    unknown = sorted(set(simulated) - set(SIMULATION_ONLY))
    if unknown:
        raise TypeError(f"data_source() got unexpected keyword argument(s): {', '.join(unknown)}")
    if sum(v is not None for v in (load, data, dic)) != 1:
        raise InputError(
            "identify: give exactly one of load= (simulated protocol), data= (measured CSV) or dic= (frames)"
        )
    given = {k: v for k, v in simulated.items() if v is not None}
    if load is not None:
        if channels is not None:
            raise InputError("channels: apply to measured data (data=, --data) only, not to a simulated case")
        if "truth_nodes" in simulated:  # given as None: the seed's same-mesh protocol
            given["truth_nodes"] = simulated["truth_nodes"]
        return SimulatedCase(load, **given)
    if given:
        names = ", ".join(f"{k} ({SIMULATION_ONLY[k]})" for k in SIMULATION_ONLY if k in given)
        kind = "measured data (data=, --data)" if data is not None else "DIC frames (dic=, --dic)"
        raise InputError(f"{names}: simulation-only option(s), used with load= (--load) only, not with {kind}")
    if dic is not None:
        if channels is not None:
            raise InputError("channels: apply to measured data (data=, --data) only, not to DIC frames")
        return DICRecord(dic)
    return MeasuredRecord(data, channels)
