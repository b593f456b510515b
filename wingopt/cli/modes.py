"""``wingopt modes``: natural frequencies and damped eigenvalues of a problem's model."""

from __future__ import annotations

import json
import time

from wingopt import resources
from wingopt.cli import options as opt
from wingopt.cli.helptext import Formatter
from wingopt.errors import InputError
from wingopt.models import build_model
from wingopt.problem import load_problem, parse_mesh
from wingopt.results import to_jsonable

ORDER = 10

EXAMPLE = """example:
  wingopt modes membrane --mesh 49x25 --count 5 --json
  wingopt modes problems/membrane.toml --count 4"""


def register(sub, common) -> None:
    p = sub.add_parser(
        "modes",
        parents=[common],
        help="natural frequencies and damped eigenvalues of a wing model",
        description="Undamped natural frequencies (ascending) and eigenvalues of the damped first-order "
        "system (positive imaginary part, ascending) of a problem's FE model.",
        epilog=EXAMPLE,
        formatter_class=Formatter,
    )
    p.add_argument("problem", help="problem file (.toml) or built-in name (membrane, plate)")
    opt.add(p, "--mesh")
    p.add_argument("--count", type=int, default=4, metavar="N", help="how many modes (default 4)")
    p.add_argument("--json", action="store_true", help="print JSON on stdout")
    p.set_defaults(func=run)


def run(args) -> int:
    problem = load_problem(args.problem)
    nodes = parse_mesh(args.mesh) if args.mesh is not None else None
    if args.count < 1:
        raise InputError(f"count = {args.count}: expected a positive integer")
    resources.check_count("--count", args.count, "modes")
    resources.check(resources.estimate_modes(nodes or problem.nodes, problem.kind, knob="--mesh"))
    t0 = time.perf_counter()
    model = build_model(problem, nodes)
    freqs = model.frequencies_hz(args.count)
    eigs = model.eigenvalues(args.count)
    wall = time.perf_counter() - t0
    if args.json:
        out = {
            "problem": problem.name,
            "mesh": list(nodes or problem.nodes),
            "frequencies_hz": freqs,
            "eigenvalues": [[e.real, e.imag] for e in eigs],
            "wall_s": wall,
        }
        print(json.dumps(to_jsonable(out)))
    else:
        nx, ny = nodes or problem.nodes
        print(f"{problem.name} on {nx}x{ny} nodes ({wall:.2f} s)")
        print(f"{'mode':>4}  {'frequency (Hz)':>16}  {'damped eigenvalue (1/s)':>30}")
        for i, (f, e) in enumerate(zip(freqs, eigs), start=1):
            print(f"{i:>4}  {f:>16.8f}  {e.real:>14.6f} {e.imag:+.6f}i")
    return 0
