"""Calibrate the plate-wing layout against Tables 5.4/5.5, or check the current problem file.

    python benchmarks/calibrate_plate.py            # check problems/plate.toml on the three meshes
    python benchmarks/calibrate_plate.py --fit      # rerun the calibration (a few minutes)
    python benchmarks/calibrate_plate.py --coarse --figures docs/img   # + the figures of docs/plate.md

The fit starts from the spec's reconstruction of Figure 5.4 (2 mm battens 25 mm wide, PZ2/PZ3 on
[0.1, 0.2], PZ8/PZ9 on [0.45, 0.6]) with the materials of problems/plate.toml, fits the batten
thickness, the edge-batten width and the spanwise positions of PZ2/PZ3 and PZ8/PZ9 on the 13x61
mesh, rounds them, and then sets the electrode spacing from the seed's twist result. It prints the
values to put into problems/plate.toml. See docs/plate.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import time
from pathlib import Path

from wingopt.plate.calibration import (
    LayoutParameters,
    apply_layout,
    calibrate,
    calibrate_electrode_spacing,
    modal_summary,
)
from wingopt.problem import load_problem

MESHES = [(7, 31), (13, 61), (25, 121)]

SPEC_START = LayoutParameters(
    batten_thickness=2.0e-3, edge_batten_width=0.025, edge_patch_start=0.1, root_patch_start=0.45
)
FREE = {
    "batten_thickness": (2.0e-3, 8.0e-3),
    "edge_batten_width": (0.02, 0.045),
    "edge_patch_start": (0.0, 0.1),
    # PZ5/PZ6 end at 0.375: keep a 5 mm gap
    "root_patch_start": (0.38, 0.5),
}


def _round(p: LayoutParameters) -> LayoutParameters:
    return p.replace(
        batten_thickness=round(p.batten_thickness, 4),
        edge_batten_width=round(p.edge_batten_width * 2000) / 2000,
        edge_patch_start=round(p.edge_patch_start * 200) / 200,
        root_patch_start=round(p.root_patch_start * 200) / 200,
    )


def check(problem, meshes) -> None:
    for nodes in meshes:
        s = modal_summary(problem, nodes, count=6)
        print(s.table())
        print(f"seed order: {s.in_seed_order}\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fit", action="store_true", help="rerun the calibration instead of checking the file")
    ap.add_argument("--problem", default="plate", help="problem file or built-in name (default plate)")
    ap.add_argument("--coarse", action="store_true", help="check 7x31 and 13x61 only")
    ap.add_argument("--figures", metavar="DIR", help="also write the layout and mode-shape figures to DIR")
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    problem = load_problem(args.problem)
    meshes = MESHES[:2] if args.coarse else MESHES
    if not args.fit:
        check(problem, meshes)
        if args.figures:
            from wingopt.plate.model import PlateModel
            from wingopt.plots import save
            from wingopt.plots.plate import layout_figure, modes_figure

            figures = Path(args.figures)
            figures.mkdir(parents=True, exist_ok=True)
            for name, fig in (
                ("plate_layout.png", layout_figure(problem)),
                ("plate_modes.png", modes_figure(PlateModel.from_problem(problem, (13, 61)))),
            ):
                save(fig, figures / name, tight=False, dpi=150)
                print(figures / name)
        return
    t0 = time.perf_counter()
    best, summary = calibrate(problem, SPEC_START, FREE)
    print(f"fit ({time.perf_counter() - t0:.0f} s): {best}")
    print(summary.table(), "\n")
    rounded = _round(best)
    fitted = apply_layout(problem, rounded)
    spacing = calibrate_electrode_spacing(fitted)
    spacing = round(spacing, 5)
    fitted = fitted.replace(piezo=dataclasses.replace(fitted.piezo, electrode_spacing=spacing))
    print("rounded:", rounded)
    print(f"[materials.batten] thickness = {rounded.batten_thickness}")
    print(f"[materials.piezo] electrode_spacing = {spacing}")
    for b in fitted.battens:
        print(f"batten {b.name!r}: rect = {[round(v, 6) for v in b.rect]}")
    for p in fitted.patches:
        print(f"patch {p.name}: rect = {[round(v, 6) for v in p.rect]}")
    print()
    check(fitted, meshes)


if __name__ == "__main__":
    main()
