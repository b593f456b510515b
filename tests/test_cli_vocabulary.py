"""One option vocabulary across the commands (issue 26, item 6; docs/cli.md).

Table-driven over every sub-command's parser: an option name that two commands share has the
same kind (flag or value), type, number of values, default and choices, unless
:data:`wingopt.cli.options.PER_COMMAND` says why it differs; a seed is ``--seed``, a count of seeds
``--n-*seeds``; the old spellings (:data:`wingopt.cli.options.DEPRECATED`) are hidden, still parse to
the same value, and warn (once, one line, on the command line).
"""

from __future__ import annotations

import argparse
import warnings

import pytest

from wingopt.cli import build_parser, main
from wingopt.cli.options import DEPRECATED, PER_COMMAND, SHARED, DeprecatedOptionWarning


def _commands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


COMMANDS = _commands()


def _visible(p: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    out = {}
    for a in p._actions:
        shown = a.help != argparse.SUPPRESS or hasattr(a, "full_help")  # --help, or --help-all (advanced)
        if not shown or isinstance(a, argparse._HelpAction):
            continue
        for s in a.option_strings:
            if s.startswith("--"):
                out[s] = a
    return out


def _meaning(a: argparse.Action) -> dict:
    return {
        "kind": type(a).__name__,
        "type": getattr(a.type, "__name__", a.type),
        "nargs": a.nargs,
        "default": a.default,
        "choices": tuple(a.choices) if a.choices else None,
    }


def _shared_names() -> dict[str, list[str]]:
    where: dict[str, list[str]] = {}
    for cmd, p in COMMANDS.items():
        for name in _visible(p):
            where.setdefault(name, []).append(cmd)
    return {n: c for n, c in where.items() if len(c) > 1}


SHARED_NAMES = _shared_names()


def test_every_command_is_audited():
    expected = {"identify", "calibrate", "compare", "sweep", "design-sensors", "gains", "morph", "modes", "demo"}
    assert expected | {"dic-sensors"} <= set(COMMANDS)


@pytest.mark.parametrize("name", sorted(SHARED_NAMES))
def test_a_shared_name_means_the_same_in_every_command(name):
    meanings = {cmd: _meaning(_visible(COMMANDS[cmd])[name]) for cmd in SHARED_NAMES[name]}
    kinds = {m["kind"] for m in meanings.values()}
    assert len(kinds) == 1, f"{name}: a flag in one command, a value in another: {meanings}"
    if name in PER_COMMAND:
        return  # documented: the default or choices depend on the command (docs/cli.md)
    first = next(iter(meanings.values()))
    differ = {cmd: m for cmd, m in meanings.items() if m != first}
    assert not differ, f"{name} differs between commands ({meanings}); make it one, or say why in PER_COMMAND"


def test_the_tables_name_options_that_exist():
    visible = {n for p in COMMANDS.values() for n in _visible(p)}
    assert set(SHARED) <= visible, set(SHARED) - visible
    assert set(PER_COMMAND) <= set(SHARED_NAMES), set(PER_COMMAND) - set(SHARED_NAMES)
    assert not set(DEPRECATED) & visible, "an old spelling is still shown by --help"


def test_a_seed_is_a_seed_and_a_count_is_named_so():
    for cmd, p in COMMANDS.items():
        opts = _visible(p)
        if "--seed" in opts:
            # identify's simulation options are unset (None) by default, so that one given with measured
            # data is refused by name; the simulation then uses 0 (PER_COMMAND)
            default = 0 if cmd != "identify" else None
            assert opts["--seed"].type is int and opts["--seed"].default == default, cmd
        for name in opts:
            if name.endswith("seeds"):
                assert name.startswith("--n-"), f"{cmd} {name}: a count of seeds is --n-...seeds"


MINIMAL = {
    "identify": ["identify", "membrane", "--load", "L1", "--out", "x"],
    "compare": ["compare", "membrane", "--out", "x"],
    "dic-sensors": ["dic-sensors", "membrane", "--out", "x"],
}
VALUES = {"--backend": "cvxpy", "--jobs": "3", "--seeds": "2", "--sign-seeds": "4", "--frames": "f.npz"}


@pytest.mark.parametrize("old", sorted(DEPRECATED))
def test_an_old_spelling_parses_the_same_and_warns(old):
    new, cmd = DEPRECATED[old]
    parser = build_parser()
    base = MINIMAL[cmd]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        want = parser.parse_args(base + [new, VALUES[old]])
    with pytest.warns(DeprecatedOptionWarning, match=f"{old} is deprecated, use {new}"):
        got = build_parser().parse_args(base + [old, VALUES[old]])
    assert vars(got) == vars(want)


def test_an_old_spelling_warns_once_in_one_line(capsys):
    # --jobs 0 is refused before any work: the deprecation line, then the error line
    assert main(["compare", "membrane", "--jobs", "0", "--seeds", "1", "--jobs", "0", "--out", "x"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0] == "wingopt compare: warning: --jobs is deprecated, use --workers (same meaning)"
    assert err[1] == "wingopt compare: warning: --seeds is deprecated, use --n-seeds (same meaning)"
    assert err[2] == "wingopt compare: error: workers = 0: expected a positive integer" and len(err) == 3
