"""One option vocabulary for every ``wingopt`` command (docs/cli.md).

An option that two commands share is defined once here (:data:`SHARED`) and added with
:func:`add`, so that the same name means the same thing everywhere: ``--seed N`` is a noise seed,
a count of seeds is ``--n-seeds N``; ``--solver`` picks the numerical solver, ``--workers`` the
worker processes. Where a shared option's default or choices differ between commands, the reason
is in :data:`PER_COMMAND` (tests/test_cli_vocabulary.py checks both tables against every parser).

Old spellings stay as hidden aliases (:data:`DEPRECATED`): they parse as before and warn once
(:class:`DeprecatedOptionWarning`; on the command line, one ``warning:`` line on stderr).

The channel-map options of ``identify`` (``--columns``, ``--gain``, ``--offset``, ``--time-column``,
``--time-unit``) are parsed here too (:func:`channel_map`).
"""

from __future__ import annotations

import argparse
import math
import re
import warnings

from wingopt.errors import InputError

__all__ = [
    "SHARED",
    "DEPRECATED",
    "PER_COMMAND",
    "DeprecatedOptionWarning",
    "add",
    "add_alias",
    "add_channel_options",
    "percent",
    "parse_noise",
    "channel_map",
    "channel_options_given",
    "parse_assignments",
]


class DeprecatedOptionWarning(FutureWarning):
    """An old option spelling was used: it still works; the message names the new one."""


MAX_MEMORY_HELP = "refuse a run estimated to need more (e.g. 4G)"

LONG_RUN_HELP = "start a run estimated over 1 day of CPU (refused)"
"""The ``--force`` help of the commands whose size estimate can refuse a run for its time
(identify, demo, morph: :func:`wingopt.resources.long_runs`)."""

SHARED: dict[str, dict] = {
    "--seed": {"type": int, "default": 0, "metavar": "N", "help": "noise seed (default 0)"},
    "--n-seeds": {"type": int, "metavar": "N", "help": "how many noise seeds"},
    "--mesh": {"metavar": "NXxNY", "help": "nodes in x and y, e.g. 25x13 (default: the problem's mesh)"},
    "--truth-mesh": {"default": "49x25", "metavar": "NXxNY", "help": "mesh of the simulated truth (default 49x25)"},
    "--t-end": {"type": float, "metavar": "S", "help": "duration, s"},
    "--max-memory": {"metavar": "SIZE", "help": MAX_MEMORY_HELP},
    "--force": {"action": "store_true", "help": LONG_RUN_HELP},
    "--noise-std": {"type": float, "metavar": "STD", "help": "sensor noise std, stretch (default: from the data)"},
    "--solver": {"metavar": "NAME", "help": "numerical solver"},
    "--method": {"metavar": "NAME", "help": "algorithm"},
    "--workers": {"type": int, "metavar": "N", "help": "worker processes"},
    "--r": {"type": float, "metavar": "R", "help": "LQR input weight R = r I, V^-2"},
    "--no-plots": {"action": "store_true", "help": "skip the figures"},
    "--json": {"action": "store_true", "help": "print the summary as JSON on stdout"},
    "--resume": {"action": "store_true", "help": "keep the records already in DIR/records.jsonl"},
}
"""Each shared option's definition (``add(parser, name, **overrides)`` adds the command's help or default)."""

DEPRECATED: dict[str, tuple[str, str]] = {
    "--backend": ("--solver", "identify"),
    "--jobs": ("--workers", "compare"),
    "--seeds": ("--n-seeds", "compare"),
    "--sign-seeds": ("--n-sign-seeds", "compare"),
    "--frames": ("--dic", "dic-sensors"),
}
"""Old spelling -> (new spelling, the command that had it). Hidden from ``--help``; they warn once."""

PER_COMMAND: dict[str, str] = {
    "--seed": "identify: unset is None (the simulation's default, 0), so that one given with measured data is "
    "refused by name; morph: 0",
    "--truth-mesh": "identify: unset is None (the simulation's default, 49x25), so that one given with measured "
    "data is refused by name; compare: 49x25",
    "--method": "the command's algorithm: an estimator (identify), a controller (morph), a fit (dic-sensors)",
    "--solver": "the command's solver: identify's MHE window solver (numpy, cvxpy, ipopt), morph's QP backend",
    "--count": "how many: modes (modes), sensors (design-sensors)",
    "--t-end": "the record's or the run's duration: identify and design-sensors 1 s, morph 2 s",
    "--workers": "compare: 1 (in this process) unless given; sweep: one per CPU core",
    "--r": "morph: 1e-14 (the sampled design, docs/control_lqr.md); gains: 1e-10 (the continuous gain, "
    "which does not converge at 1e-14: wingopt.control.riccati_large.GAIN_R); both applied when not given",
    "--noise": "noise in PERCENT of each sensor's peak everywhere; compare takes a list (1,5)",
    "--noise-percent": "the same option as --noise, its unit in the name (identify, design-sensors)",
    "--load-space": "identify: unset means fixed (its estimator's default); compare: fixed",
    "--state-prior": "identify: unset means 1 (its estimator's default); compare: 1",
    "--out": "the output directory everywhere; demo has a default (./wingopt-demo)",
    "--data": "a CSV record; identify also takes '-' (standard input)",
    "--mesh": "the estimator's or the model's mesh; default: the problem's",
    "--force": "do what is refused by default: identify, demo, morph start a run estimated beyond the time limit "
    "(1 day of CPU); calibrate, compare, design-sensors let an output file replace an existing one",
}
"""Shared names whose default or choices depend on the command, and why (documented in docs/cli.md)."""


class _DeprecatedAlias(argparse.Action):
    """An old spelling: warns, then does what the new option does."""

    def __init__(self, option_strings, dest, canonical=None, **kwargs) -> None:
        super().__init__(option_strings, dest, **kwargs)
        self.canonical = canonical

    def __call__(self, parser, namespace, values, option_string=None):
        new = self.canonical.option_strings[-1]
        warnings.warn(f"{option_string} is deprecated, use {new} (same meaning)", DeprecatedOptionWarning, stacklevel=2)
        self.canonical(parser, namespace, values, new)


def add_alias(container, action: argparse.Action, old: str) -> argparse.Action:
    """Add ``old`` as a hidden, deprecated spelling of ``action`` (same destination, type and choices)."""
    return container.add_argument(
        old,
        dest=action.dest,
        nargs=action.nargs,
        type=action.type,
        choices=action.choices,
        metavar=action.metavar,
        default=argparse.SUPPRESS,
        help=argparse.SUPPRESS,
        action=_DeprecatedAlias,
        canonical=action,
    )


def add(container, name: str, *, aliases: tuple[str, ...] = (), **overrides) -> argparse.Action:
    """Add the shared option ``name`` (:data:`SHARED`) with the command's ``overrides`` (help, default,
    choices, dest); ``aliases``: old spellings, hidden and deprecated."""
    kwargs = dict(SHARED.get(name, {}))
    kwargs.update(overrides)
    action = container.add_argument(name, **kwargs)
    for old in aliases:
        add_alias(container, action, old)
    return action


def parse_noise(text: str) -> float:
    """``"1"`` or ``"1%"`` -> 0.01. Percent is the unit; bare values in (0, 0.1) are ambiguous."""
    from wingopt.values import NoiseLevel

    s = str(text).strip()
    m = re.fullmatch(r"([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(%?)", s)
    if not m:
        raise InputError(f"noise = {text!r}: expected a percentage, e.g. 1 for 1 % (or '1%')")
    value, pct = float(m.group(1)), m.group(2) == "%"
    if not pct and 0 < value < 0.1:
        raise InputError(
            f"noise = {text!r}: ambiguous, the noise is in percent (1 means 1 %); "
            f"for {100 * value:g} % write {100 * value:g}, for {value:g} % write '{value:g}%'"
        )
    return NoiseLevel.from_percent(value).fraction


def percent(text: str) -> float:
    """An argparse ``type``: ``"1"`` or ``"1%"`` -> 1.0 (percent), with :func:`parse_noise`'s rule
    (bare values in (0, 0.1) are ambiguous and refused, in one line)."""
    try:
        return 100 * parse_noise(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


# -- the channel map (identify --columns/--gain/--offset) ---------------------------------------


def parse_assignments(text: str, option: str, number: bool) -> dict:
    """``"S1=ch1,S2=ch2"`` -> ``{"S1": "ch1", ...}``; with ``number``, values are floats and a bare
    number (``"1e-5"``) applies to every sensor (key ``"*"``). One-line :class:`InputError` naming ``option``."""
    from wingopt.measurements.channels import ALL

    s = str(text).strip()
    if number and re.fullmatch(r"[-+]?[0-9.]+(?:[eE][-+]?[0-9]+)?|[-+]?(?:inf|nan)", s, flags=re.I):
        return {ALL: _number(s, option, ALL)}
    out: dict = {}
    for item in s.split(","):
        name, eq, value = item.partition("=")
        name, value = name.strip(), value.strip()
        if not eq or not name or not value:
            example = "S1=1e-5,S2=1.1e-5 (or one number for all)" if number else "S1=ch1,S2=ch2"
            raise InputError(f"{option} {text!r}: expected SENSOR=VALUE pairs separated by commas, e.g. {example}")
        if name in out:
            raise InputError(f"{option} {text!r}: {name} is given twice")
        out[name] = _number(value, option, name) if number else value
    return out


def _number(value: str, option: str, name: str) -> float:
    try:
        v = float(value)
    except ValueError:
        raise InputError(f"{option}: {name} = {value!r}: expected a number") from None
    if not math.isfinite(v):
        raise InputError(f"{option}: {name} = {value!r}: expected a finite number")
    if option == "--gain" and v == 0:
        raise InputError(f"{option}: {name} = 0: expected a non-zero stretch per raw unit (e.g. 1e-5 per mV)")
    return v


def add_channel_options(parser):
    """``--columns``, ``--gain``, ``--offset``, ``--time-column``, ``--time-unit`` (identify's CSV data);
    returns their argument group."""
    from wingopt.measurements.channels import TIME_UNITS

    # stretch = gain * (raw - offset) per sensor; sensors not named keep their column, gain 1, offset 0
    g = parser.add_argument_group("measured data (--data, --follow; stretch = gain * (raw - offset))")
    g.add_argument("--columns", metavar="S1=COL,...", help="each sensor's CSV column, e.g. S1=ch1,S2=ch2")
    g.add_argument("--gain", metavar="S1=G,...", help="stretch per raw unit, per sensor (or one for all)")
    g.add_argument("--offset", metavar="S1=O,...", help="raw reading at zero stretch, per sensor (or one)")
    g.add_argument("--time-column", metavar="NAME", help="the time column (default t)")
    g.add_argument(
        "--time-unit", choices=tuple(TIME_UNITS), metavar="UNIT", help=f"time unit: {', '.join(TIME_UNITS)} (default s)"
    )
    return g


def channel_options_given(args) -> bool:
    """Whether any of the channel-map options is on the command line."""
    return any(getattr(args, k, None) is not None for k in ("columns", "gain", "offset", "time_column", "time_unit"))


def channel_map(args, problem):
    """The :class:`~wingopt.measurements.channels.ChannelMap` of the problem's ``[measurements]``
    table with the command line's entries over it, checked against the problem's sensors; ``None``
    when neither gives one."""
    from wingopt.measurements.channels import ChannelMap

    given = {
        "columns": parse_assignments(args.columns, "--columns", False) if args.columns is not None else None,
        "gain": parse_assignments(args.gain, "--gain", True) if args.gain is not None else None,
        "offset": parse_assignments(args.offset, "--offset", True) if args.offset is not None else None,
        "time": args.time_column,
        "time_unit": args.time_unit,
    }
    base = getattr(problem, "measurements", None)
    if all(v is None for v in given.values()):
        return base
    where = "command line" if base is None else f"{base.declared_in} + command line"
    try:
        return (base or ChannelMap()).updated(declared_in=where, **given).check(problem.sensor_names)
    except InputError as exc:
        msg = str(exc)
        for field, option in _FIELDS.items():
            if msg.startswith(field):
                msg = option + msg[len(field) :]
                break
        raise InputError(msg) from None


_FIELDS = {
    "columns": "--columns",
    "gain": "--gain",
    "offset": "--offset",
    "time_unit": "--time-unit",
    "time": "--time-column",
}
