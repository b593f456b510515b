"""A tour of the Python API (the README's, runnable): problems, models, morphing, identification.

.venv/bin/python examples/tour.py            # ~1 minute
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import wingopt as wo


def main(quick: bool = False, out: Path | None = None) -> dict:
    out = Path(out or tempfile.mkdtemp(prefix="wingopt-tour-"))
    numbers: dict = {}

    # 1. Problems are validated TOML files; models are assembled from them (any mesh).
    plate = wo.load_problem("plate")
    model = wo.build_model(plate, (7, 31) if quick else None)
    numbers["plate_hz"] = model.frequencies_hz(4)
    print("plate frequencies (Hz):", numbers["plate_hz"].round(3))

    # 2. Morph into twist within -500/+1500 V with the QP, and the seed's LQR saturated alike.
    nodes = (7, 31) if quick else None
    qp = wo.morph(plate, "twist", method="qp", nodes=nodes)
    lqr = wo.morph(plate, "twist", method="lqr", vmin=-500, vmax=1500, nodes=nodes)
    numbers["qp_shape_error"] = qp.summary()["shape_error"]
    numbers["lqr_shape_error"] = lqr.summary()["shape_error"]
    print(f"twist shape error: QP {numbers['qp_shape_error']:.4f}, saturated LQR {numbers['lqr_shape_error']:.4f}")
    wo.write_morph_outputs(qp, out / "twist", compare_with=lqr)

    # 3. Identify a load from four stretch sensors (truth simulated on a finer mesh).
    membrane = wo.load_problem("membrane")
    run = wo.identify(membrane, load="L1", noise_percent=1, seed=0, method="mhe")
    s = run.summary()
    numbers["mhe_load_error"] = s["load_error"]
    print(
        f"L1: load error {s['load_error']:.4f}, lift {s['lift_N']:.4f} ± {s['lift_std_N']:.4f} N "
        f"(true {s['true_lift_N']:.4f})"
    )
    wo.write_identify_outputs(run, out / "L1")

    # 4. The same from a measured record (here the package's synthetic wind-tunnel stand-in).
    data = Path(__file__).parent / "data" / "tunnel_300Hz.csv"
    meas, report = wo.read_measurements(data, membrane.sensor_names)
    numbers["csv_rows"], numbers["csv_missing"] = report.rows, report.missing_rows
    print(f"{data.name}: {report.rows} rows at {1 / report.dt:.0f} Hz, {report.missing_rows} missing")

    # 5. Interop: the membrane's state space in python-control, a field in ParaView.
    ss = wo.build_model(membrane).system.state_space()
    try:
        numbers["control_states"] = ss.to_control().nstates
        print("python-control system with", numbers["control_states"], "states")
    except ImportError:
        print("python-control not installed (pip install 'wingopt[interop]')")
    try:
        from wingopt.results.vtk import export_vtk

        export_vtk(out / "L1_load.vtu", run.model.space, {"pressure": run.load_field()})
        print("VTK file:", out / "L1_load.vtu")
    except ImportError:
        print("meshio not installed (pip install 'wingopt[interop]')")
    print("outputs in", out)
    return numbers


if __name__ == "__main__":
    main(quick="--quick" in sys.argv)
