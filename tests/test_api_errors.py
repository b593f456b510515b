"""The public API raises the package's errors (issue 25): every function reachable from
``wingopt.__all__`` and the documented classes (``MovingHorizonEstimator``, ``wingopt.control.lqr``/
``dlqr``/``lqe``, ``MembraneModel.from_problem``, ``design_sensors``, ``follow``, ``identify``,
``calibrate_membrane``, the result writers) answers a wrong type, shape, dtype, size or NaN with a
:class:`~wingopt.errors.WingoptError` (``InputError`` & co.) whose message is one line naming the
argument, before any work: never a bare ``TypeError``/``ValueError``/``AttributeError``/``MemoryError``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

import wingopt as wo
from wingopt.errors import WingoptError
from wingopt.workflows.sources import SIMULATION_ONLY

ROOT = Path(__file__).resolve().parents[1]
REC = ROOT / "examples" / "data" / "tunnel_calibration_300Hz.csv"  # any shipped record: every call is refused
NAMES = ("S1", "S2", "S3", "S4")
NAN = float("nan")


def _p13():
    return wo.load_problem("membrane").with_mesh((13, 7))


def _model():
    from wingopt.membrane import MembraneModel

    return MembraneModel.from_problem(_p13())


SIM = {"load": "L1", "t_end": 0.2, "nodes": (13, 7), "truth_nodes": (19, 10)}


def _identify(**kw):
    args = {**SIM, **kw}
    if "data" in kw:  # measured data: the simulated case's options are refused, so they are left out
        args = {k: v for k, v in args.items() if k not in SIMULATION_ONLY and k != "load"}
    return wo.identify(_p13(), **args)


def _lqr(*args):
    from wingopt.control import lqr

    return lqr(*args)


def _dlqr(*args):
    from wingopt.control import dlqr

    return dlqr(*args)


def _lqe(*args):
    from wingopt.control.lqr import lqe

    return lqe(*args)


def _mhe(*args, setup=None):
    from wingopt.estimation.mhe import MovingHorizonEstimator

    est = MovingHorizonEstimator(*args)
    if setup is not None:
        est.setup(setup)


def _design(*args, **kw):
    from wingopt.design import design_sensors

    return design_sensors(_p13(), *args, **kw)


def _follow(tmp, **kw):
    from wingopt.workflows.stream import follow

    args = {"problem": _p13(), "out": tmp / "res", "source": str(REC), "idle_timeout": 0.5}
    args.update(kw)
    return follow(args.pop("problem"), args.pop("out"), **args)


def _calibrate(problem="membrane", data=str(REC), **kw):
    from wingopt.workflows.calibrate import calibrate_membrane

    return calibrate_membrane(problem, data, **kw)


def _model_from(problem, nodes=None, kind="membrane"):
    if kind == "membrane":
        from wingopt.membrane import MembraneModel

        return MembraneModel.from_problem(problem, nodes)
    from wingopt.plate import PlateModel

    return PlateModel.from_problem(problem, nodes)


def _measurements(t, values, names=("S1",)):
    from wingopt.measurements import Measurements

    return Measurements(t, values, names)


def _stream_push(t, y):
    from wingopt.estimation.streaming import StreamingEstimator

    e = StreamingEstimator(_model())
    e.push(0.0, [1e-4] * 4)
    e.push(t, y)


def _writer(what, tmp):
    from wingopt.results import OwnedDirectory, ResultDirectory, check_writable, write_text_atomic

    if what == "ResultDirectory(123)":
        ResultDirectory(123)
    elif what == "check_writable(file)":
        (tmp / "f.txt").write_text("mine")
        check_writable(tmp / "f.txt")
    elif what == "write_text_atomic(existing)":
        (tmp / "f.txt").write_text("mine")
        write_text_atomic(tmp / "f.txt", "x", what="doc")
    elif what == "OwnedDirectory(foreign)":
        (tmp / "d").mkdir()
        (tmp / "d" / "notes.txt").write_text("mine")
        OwnedDirectory(tmp / "d")


# (id, call(tmp), words: one of them must be in the message)
CASES = [
    # -- wingopt.__all__ ---------------------------------------------------------------------------
    ("load_problem(None)", lambda t: wo.load_problem(None), ["problem"]),
    ("load_problem(123)", lambda t: wo.load_problem(123), ["problem"]),
    ("load_problem(bytes)", lambda t: wo.load_problem(b"membrane"), ["problem"]),
    ("load_problem(dict)", lambda t: wo.load_problem({"kind": "membrane"}), ["problem"]),
    ("load_problem(/dev/zero)", lambda t: wo.load_problem("/dev/zero"), ["/dev/zero"]),
    ("load_problem(dir)", lambda t: wo.load_problem(t), ["directory"]),
    ("parse_mesh(None)", lambda t: wo.parse_mesh(None), ["mesh"]),
    ("plot_lift(None)", lambda t: wo.plot_lift(None), ["run", "IdentifyRun"]),
    ("plot_field(None)", lambda t: wo.plot_field(None), ["run", "IdentifyRun"]),
    ("parse_mesh(137)", lambda t: wo.parse_mesh(137), ["mesh"]),
    ("build_model(None)", lambda t: wo.build_model(None), ["problem"]),
    ("build_model(mesh '13x7')", lambda t: wo.build_model(_p13(), "13x7"), ["nodes"]),
    ("build_model(mesh (13,))", lambda t: wo.build_model(_p13(), (13,)), ["nodes"]),
    ("build_model(mesh (13.5, 7))", lambda t: wo.build_model(_p13(), (13.5, 7)), ["nodes"]),
    ("build_model(mesh (nan, 7))", lambda t: wo.build_model(_p13(), (NAN, 7)), ["nodes"]),
    ("build_model(10000x10000)", lambda t: wo.build_model(_p13(), (10000, 10000)), ["mesh"]),
    ("build_model(plate 10000x10000)", lambda t: wo.build_model(wo.load_problem("plate"), (10000, 10000)), ["mesh"]),
    ("morph(membrane)", lambda t: wo.morph(wo.load_problem("membrane"), "twist"), ["problem"]),
    ("morph(shape=None)", lambda t: wo.morph(wo.load_problem("plate"), None, "lqr", nodes=(7, 31)), ["shape"]),
    ("morph(t_end=nan)", lambda t: wo.morph(wo.load_problem("plate"), "twist", "lqr", t_end=NAN), ["t_end"]),
    ("morph(t_end='1')", lambda t: wo.morph(wo.load_problem("plate"), "twist", "lqr", t_end="1"), ["t_end"]),
    ("morph(vmin='a')", lambda t: wo.morph(wo.load_problem("plate"), "twist", "qp", vmin="a"), ["vmin"]),
    ("morph(seed=None)", lambda t: wo.morph(wo.load_problem("plate"), "twist", "lqr", seed=None), ["seed"]),
    ("morph(method=1)", lambda t: wo.morph(wo.load_problem("plate"), "twist", 1), ["method"]),
    ("morph(nodes='7x31')", lambda t: wo.morph(wo.load_problem("plate"), "twist", "lqr", nodes="7x31"), ["nodes"]),
    ("morph(horizon=100000)", lambda t: wo.morph(wo.load_problem("plate"), "twist", "qp", horizon=100000), ["horizon"]),
    ("morph(horizn=5)", lambda t: wo.morph(wo.load_problem("plate"), "twist", "qp", horizn=5), ["horizn"]),
    ("write_morph_outputs('x')", lambda t: wo.write_morph_outputs("x", t / "res"), ["result"]),
    ("identify(None)", lambda t: wo.identify(None, **SIM), ["problem"]),
    ("identify(noise=0.01)", lambda t: _identify(noise=0.01), ["noise"]),
    ("identify(noise_percent=nan)", lambda t: _identify(noise_percent=NAN), ["noise"]),
    ("identify(seed=1.5)", lambda t: _identify(seed=1.5), ["seed"]),
    ("identify(t_end='0.2')", lambda t: _identify(t_end="0.2"), ["t_end"]),
    ("identify(nodes='13x7')", lambda t: _identify(nodes="13x7"), ["nodes"]),
    ("identify(truth_nodes=(3, 3))", lambda t: _identify(truth_nodes=(3, 3)), ["truth_nodes"]),
    ("identify(load='L9')", lambda t: _identify(load="L9"), ["load"]),
    ("identify(truth_damping=nan)", lambda t: _identify(truth_damping=NAN), ["damping"]),
    ("identify(truth_prestrain=(nan, 1))", lambda t: _identify(truth_prestrain=(NAN, 1.0)), ["prestrain"]),
    ("identify(max_memory=-1)", lambda t: _identify(max_memory=-1), ["max_memory"]),
    ("identify(settings='x')", lambda t: _identify(settings="x"), ["settings"]),
    ("identify(lam=-1)", lambda t: _identify(lam=-1.0), ["lambda"]),
    ("identify(initial_load=nan)", lambda t: _identify(initial_load=NAN), ["initial_load"]),
    ("identify(noise_std=[1, 2])", lambda t: _identify(data=str(REC), noise_std=[1.0, 2.0]), ["noise_std"]),
    ("identify(noise_std=1e308)", lambda t: _identify(data=str(REC), noise_std=1e308), ["noise_std"]),
    ("identify(data=all-NaN)", lambda t: _identify(data=np.full((200, 5), NAN)), ["data"]),
    ("identify(data=empty)", lambda t: _identify(data=np.zeros((0, 5))), ["data"]),
    ("identify(data=123)", lambda t: _identify(data=123), ["data"]),
    ("identify(data=objects)", lambda t: _identify(data=np.array([["a"] * 5] * 50, dtype=object)), ["data"]),
    ("identify(data=complex)", lambda t: _identify(data=np.ones((50, 5)) * 1j), ["data"]),
    ("identify(data=wrong width)", lambda t: _identify(data=np.ones((50, 3))), ["data"]),
    ("identify(method=1)", lambda t: _identify(method=1), ["method"]),
    ("write_identify_outputs(None)", lambda t: wo.write_identify_outputs(None, t / "res"), ["run"]),
    ("read_measurements(None)", lambda t: wo.read_measurements(None, NAMES), ["path"]),
    ("read_measurements(names str)", lambda t: wo.read_measurements(REC, "S1S2S3S4"), ["sensor_names"]),
    ("read_measurements(names [])", lambda t: wo.read_measurements(REC, []), ["sensor_names"]),
    ("read_measurements(/dev/zero)", lambda t: wo.read_measurements("/dev/zero", NAMES), ["/dev/zero"]),
    ("read_measurements(dir)", lambda t: wo.read_measurements(t, NAMES), ["directory"]),
    ("run_demo(config='quick')", lambda t: wo.run_demo(t / "res", config="quick"), ["config"]),
    ("run_demo(progress='yes')", lambda t: wo.run_demo(t / "res", progress="yes"), ["progress"]),
    ("run_demo(out=123)", lambda t: wo.run_demo(123), ["out"]),
    # -- documented classes and functions -------------------------------------------------------------
    ("MembraneModel.from_problem(plate)", lambda t: _model_from(wo.load_problem("plate")), ["problem"]),
    ("MembraneModel.from_problem(None)", lambda t: _model_from(None), ["problem"]),
    ("MembraneModel.from_problem((0, 0))", lambda t: _model_from(wo.load_problem("membrane"), (0, 0)), ["nodes"]),
    ("MembraneModel.from_problem(10000x10000)", lambda t: _model_from(_p13(), (10000, 10000)), ["mesh"]),
    ("PlateModel.from_problem(membrane)", lambda t: _model_from(_p13(), kind="plate"), ["problem"]),
    ("MovingHorizonEstimator(None)", lambda t: _mhe(None), ["model"]),
    ("MovingHorizonEstimator(model, 'x')", lambda t: _mhe(_model(), "x"), ["settings"]),
    ("MovingHorizonEstimator.setup('x')", lambda t: _mhe(_model(), setup="x"), ["measurements"]),
    ("lqr(B wrong rows)", lambda t: _lqr(np.eye(2), np.ones((3, 1)), np.eye(2), np.eye(1)), ["B"]),
    ("lqr(NaN in A)", lambda t: _lqr(np.array([[0, NAN], [0, 0]]), np.ones((2, 1)), np.eye(2), np.eye(1)), ["A"]),
    ("lqr(strings)", lambda t: _lqr("a", "b", "c", "d"), ["A"]),
    ("lqr(one argument)", lambda t: _lqr(np.eye(2)), ["argument"]),
    ("lqr(R not PD)", lambda t: _lqr(-np.eye(2), np.eye(2), np.eye(2), -np.eye(2)), ["R"]),
    ("lqr(1-D)", lambda t: _lqr(np.ones(3), np.ones(3), np.ones(3), np.ones(1)), ["A"]),
    ("lqr(complex)", lambda t: _lqr(np.eye(2) * 1j, np.ones((2, 1)), np.eye(2), np.eye(1)), ["A"]),
    ("dlqr(B wrong rows)", lambda t: _dlqr(np.eye(3), np.ones((2, 1)), np.eye(3), np.eye(1)), ["B"]),
    ("lqe(G wrong rows)", lambda t: _lqe(np.eye(2), np.ones((3, 1)), np.eye(2), np.eye(1), np.eye(2)), ["G"]),
    ("design_sensors(count=-1)", lambda t: _design(-1), ["count"]),
    ("design_sensors(count=2.5)", lambda t: _design(2.5), ["count"]),
    ("design_sensors(count=True)", lambda t: _design(True), ["count"]),
    ("design_sensors(count=10**6)", lambda t: _design(10**6), ["count"]),
    ("design_sensors(candidates=123)", lambda t: _design(2, 123), ["candidates"]),
    ("design_sensors(settings='x')", lambda t: _design(2, None, "x"), ["settings"]),
    ("design_sensors(crit=..)", lambda t: _design(2, crit="a"), ["crit"]),
    ("follow(problem=None)", lambda t: _follow(t, problem=None), ["problem"]),
    ("follow(source=dir)", lambda t: _follow(t, source=str(t)), ["follow"]),
    ("follow(source=/dev/zero)", lambda t: _follow(t, source="/dev/zero"), ["/dev/zero"]),
    ("follow(source=123)", lambda t: _follow(t, source=123), ["source"]),
    ("follow(poll=inf)", lambda t: _follow(t, poll=float("inf")), ["poll"]),
    ("follow(idle_timeout=-1)", lambda t: _follow(t, idle_timeout=-1), ["idle"]),
    ("follow(options='x')", lambda t: _follow(t, options="x"), ["options"]),
    ("follow(stop='x')", lambda t: _follow(t, stop="x"), ["stop"]),
    ("follow(out=123)", lambda t: _follow(t, out=123), ["out"]),
    ("follow(out=the input's dir)", lambda t: _follow(t, out=REC.parent), ["input"]),
    ("calibrate_membrane(plate)", lambda t: _calibrate("plate"), ["problem"]),
    ("calibrate_membrane(data=None)", lambda t: _calibrate(data=None), ["data"]),
    ("calibrate_membrane(noise_std=1e308)", lambda t: _calibrate(noise_std=1e308), ["noise_std"]),
    ("calibrate_membrane(release_peak=nan)", lambda t: _calibrate(release_peak=NAN), ["release_peak"]),
    ("calibrate_membrane(data=dir)", lambda t: _calibrate(data=t), ["directory"]),
    ("calibrated_problem(None)", lambda t: wo.calibrated_problem(None), ["run", "CalibrationRun"]),
    ("Measurements(complex t)", lambda t: _measurements(np.arange(3) * 1j, np.ones((3, 1))), ["t"]),
    ("Measurements(shapes)", lambda t: _measurements(np.arange(10.0), np.ones((7, 1))), ["t", "values"]),
    ("Measurements(names str)", lambda t: _measurements(np.arange(3.0), np.ones((3, 1)), "S1"), ["sensor_names"]),
    ("StreamingEstimator.push(wrong length)", lambda t: _stream_push(0.01, [1e-4, 1e-4]), ["y", "sensor"]),
    ("StreamingEstimator.push(t=nan)", lambda t: _stream_push(NAN, [1e-4] * 4), ["t"]),
    ("ResultDirectory(123)", lambda t: _writer("ResultDirectory(123)", t), ["out"]),
    ("check_writable(a file)", lambda t: _writer("check_writable(file)", t), ["out"]),
    ("write_text_atomic(existing)", lambda t: _writer("write_text_atomic(existing)", t), ["doc", "exists"]),
    ("OwnedDirectory(foreign)", lambda t: _writer("OwnedDirectory(foreign)", t), ["out"]),
]


@pytest.mark.parametrize("call, words", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_wrong_argument_is_one_line_wingopt_error_naming_it(call, words, tmp_path):
    t0 = time.perf_counter()
    with pytest.raises(WingoptError) as info:
        call(tmp_path)
    msg = str(info.value)
    assert "\n" not in msg.strip(), msg
    assert any(w.lower() in msg.lower() for w in words), f"{words} not in: {msg}"
    assert time.perf_counter() - t0 < 30  # refused before any work (size checks included)


def test_every_public_function_is_covered():
    covered = {c[0].split("(")[0] for c in CASES}
    public = {name for name in wo.__all__ if name != "__version__"}
    assert public <= covered, sorted(public - covered)
