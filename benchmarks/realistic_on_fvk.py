"""The realistic estimator and the linear MHE on Föppl–von Kármán truth records (issue 11).

FvK membrane on 49x25 (``wingopt.membrane.simulate_record(truth="fvk")``), the seed's protocol,
1 % noise, seed 0; one JSON line per (load, estimator) with lift error / ∫|P|, field error, band,
coverage, adequacy flag, identified parameters and CPU time::

    nice python benchmarks/realistic_on_fvk.py L1,LE,L2 > fvk.jsonl
    nice python benchmarks/realistic_on_fvk.py L1 --stretch-gain 1.45 --estimators realistic
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from wingopt.estimation.realistic import RealisticSettings, realistic_identify  # noqa: E402
from wingopt.estimation.realistic.mhe_check import check_mhe_result  # noqa: E402
from wingopt.fe import integrate  # noqa: E402
from wingopt.membrane import MembraneModel, simulate_record  # noqa: E402
from wingopt.problem import load_problem  # noqa: E402
from wingopt.workflows.protocols import relative_l2  # noqa: E402
from wingopt.workflows.studies import load_field, run_method  # noqa: E402


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("loads", help="comma-separated: L1,L2,L3,LE")
    ap.add_argument("--noise", type=float, default=0.01)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--stretch-gain", type=float, default=1.0)
    ap.add_argument("--estimators", default="realistic,mhe")
    a = ap.parse_args(argv)
    problem = load_problem("membrane")
    model = MembraneModel.from_problem(problem)
    settings = RealisticSettings(stretch_gain=a.stretch_gain)
    for load in a.loads.split(","):
        rec = simulate_record(problem, load, truth="fvk", noise=a.noise, seed=a.seed)
        meas = dataclasses.replace(rec.to_measurements(), noise_std=None)
        absl = integrate(rec.model.space, lambda x, y, p=rec.load: np.abs(p(x, y)), order=8)
        for est in a.estimators.split(","):
            c0 = time.process_time()
            if est == "realistic":
                res = realistic_identify(model, meas, settings)
            else:
                res = check_mhe_result(model, meas, run_method("mhe", model, meas))
            cpu = time.process_time() - c0
            lt = float(rec.lift[-1])
            out = {
                "truth": "fvk 49x25",
                "load": load,
                "estimator": est if est != "realistic" else f"realistic (stretch gain {a.stretch_gain:g})",
                "lift": float(res.lift[-1]),
                "lift_true": lt,
                "lift_std": float(res.lift_std[-1]),
                "lift_error": float((res.lift[-1] - lt) / absl),
                "load_error": relative_l2(rec.model.space, rec.load_field(), load_field(res, model)),
                "covered": bool(abs(res.lift[-1] - lt) <= res.lift_std[-1]),
                "adequate": res.info.get("model_adequate"),
                "chi2": (res.info.get("adequacy") or {}).get("chi2_per_datum"),
                "params": res.info.get("parameters"),
                "selection": (res.info.get("membrane_selection") or {}).get("chosen"),
                "warnings": res.info.get("warnings"),
                "cpu_s": cpu,
            }
            print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
