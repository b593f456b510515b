"""``wingopt dic-sensors``: virtual stretch sensors from DIC frames, as a record ``wingopt identify --data`` reads.

The frames (an ``.npz`` file in the plain layout, a directory of DICe solution files or of CSV
frames) are mapped to the wing by the problem's ``[dic]`` table; the problem's sensors are emulated
(``--kind slope``, the default: a smooth fit of the deflection, then the sensor's own definition;
``strain``: the seed's route, the rectangle mean of the surface Lagrange strain's trace, which also
holds the in-plane stretch). Writes ``sensors.csv`` (``t`` + one column per sensor, ``nan`` where a
frame has too few valid points), ``initial_shape.csv`` (the first frame's deflection) and
``summary.json`` into ``--out``, atomically.
"""

from __future__ import annotations

import json

from wingopt.cli import options as opt
from wingopt.cli.helptext import Formatter
from wingopt.membrane.virtual_sensors import KINDS, METHODS
from wingopt.results import check_writable, to_jsonable
from wingopt.workflows.dic import dic_sensors, write_dic_sensors_outputs

ORDER = 32

EXAMPLE = """examples:
  wingopt dic-sensors membrane --dic examples/data/tunnel_dic_300Hz.npz --out runs/vs
  wingopt identify membrane --data runs/vs/sensors.csv --out runs/vs_id      # any estimator of sensor series
  wingopt dic-sensors examples/tunnel_dice.toml --dic examples/data/tunnel_dice --out runs/dice
  wingopt identify membrane --dic examples/data/tunnel_dic_300Hz.npz --out runs/ff   # the full field instead
  (the [dic] table of the problem maps DICe coordinates to the wing: docs/dic.md)"""


def register(sub, common) -> None:
    p = sub.add_parser(
        "dic-sensors",
        parents=[common],
        help="emulate the stretch sensors from DIC frames (a CSV record for identify --data)",
        description="Virtual stretch sensors from DIC frames: the problem's sensor rectangles integrated over every "
        "frame, written as a sensor record (t + one column per sensor) that wingopt identify --data reads.",
        epilog=EXAMPLE,
        formatter_class=Formatter,
    )
    p.add_argument("problem", help="problem file (.toml; its [dic] table maps the frames) or built-in name (membrane)")
    src = p.add_mutually_exclusive_group(required=True)  # --frames: the old spelling
    opt.add(src, "--dic", dest="frames", metavar="DIR|FILE.npz", help="the DIC frames", aliases=("--frames",))
    p.add_argument(
        "--kind",
        choices=KINDS,
        default="slope",
        help="slope (default): the sensor's definition on a fit of W; strain: the seed's strain-trace mean "
        "(includes the in-plane stretch); strain_minus_inplane: that less the fitted in-plane part",
    )
    opt.add(p, "--method", choices=METHODS, default="fit", help="fit (default) or points (strain kinds only)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (replaced atomically)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    p.set_defaults(func=run)


def run(args) -> int:
    check_writable(args.out)
    run_ = dic_sensors(args.problem, args.frames, kind=args.kind, method=args.method)
    write_dic_sensors_outputs(run_, args.out)
    summary = to_jsonable(run_.summary())
    if args.json:
        print(json.dumps(summary))
        return 0
    d = summary["dic"]
    print(
        f"dic-sensors: {summary['samples']} frames x {d['points']} points ({d['valid_fraction']:.1%} valid), "
        f"{d['route']}, first frame's peak {1e3 * d['initial_shape']['peak_m']:.2f} mm -> {args.out}/sensors.csv"
    )
    return 0
