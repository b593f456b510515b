"""Membrane wing: FE model, stretch sensors, loads, forward models and simulated records (chapter 6, §8).

* :class:`MembraneModel` (:mod:`.model`): the linear FE operators on one mesh (spec §2);
* :mod:`.forward`: the forward-model protocol and :func:`forward_model` — linear, Berger and
  Föppl–von Kármán physics, full order (:mod:`.full`) or modal (:mod:`.modal`);
* :func:`simulate_truth` (:mod:`.truth`): a simulated record with its truth, from any forward
  model, load and :class:`RecordProtocol`;
* loads (:mod:`.loads`), stretch sensors (:mod:`.sensors`), :class:`MembraneParameters`.
"""

from wingopt.membrane.forward import PHYSICS, ForwardRecord, MembraneForward, forward_model
from wingopt.membrane.loads import (
    LOAD_CASES,
    TUNNEL_LOADS,
    Buffeting,
    Gust,
    PressureLoad,
    bubble,
    leading_edge_load,
    load_case,
    tunnel_load,
)
from wingopt.membrane.model import MembraneModel, membrane_space
from wingopt.membrane.parameters import MembraneParameters
from wingopt.membrane.sensors import StretchSensors, add_noise, noise_std_for
from wingopt.membrane.truth import RecordProtocol, Trajectory, TruthRecord, relative_l2, simulate_truth

__all__ = [
    "MembraneModel",
    "membrane_space",
    "StretchSensors",
    "add_noise",
    "noise_std_for",
    "PressureLoad",
    "load_case",
    "leading_edge_load",
    "bubble",
    "Gust",
    "Buffeting",
    "tunnel_load",
    "TUNNEL_LOADS",
    "LOAD_CASES",
    "MembraneParameters",
    "PHYSICS",
    "ForwardRecord",
    "MembraneForward",
    "forward_model",
    "RecordProtocol",
    "Trajectory",
    "TruthRecord",
    "simulate_truth",
    "relative_l2",
]
