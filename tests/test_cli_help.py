"""Every command's --help fits one screen at 80 columns; one metavar per option; --help-all shows the rest."""

from __future__ import annotations

import argparse
import math
import re

import pytest

from wingopt.cli import build_parser
from wingopt.cli.helptext import MAX_LINES

WIDTH = 80


def _commands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _screen_lines(text: str) -> int:
    """Lines as a terminal of WIDTH columns shows them (a longer line takes several)."""
    return sum(max(1, math.ceil(len(line) / WIDTH)) for line in text.splitlines())


@pytest.fixture(autouse=True)
def _columns(monkeypatch):
    monkeypatch.setenv("COLUMNS", str(WIDTH))
    monkeypatch.setenv("LINES", "24")


COMMANDS = sorted(_commands())


def test_every_command_is_counted():
    assert {"identify", "design-sensors", "calibrate", "compare", "morph", "demo", "sweep"} <= set(COMMANDS)


@pytest.mark.parametrize("name", COMMANDS)
def test_help_fits_one_screen(name):
    text = _commands()[name].format_help()
    n = _screen_lines(text)
    assert n <= MAX_LINES, f"wingopt {name} --help: {n} lines at {WIDTH} columns"
    assert max(len(line) for line in text.splitlines()) <= WIDTH


def test_top_level_help_is_current():
    text = build_parser().format_help()
    assert "(MHE or JEKF)" not in text
    entry = re.search(r"^ {4}identify +(.+(?:\n {10,}.+)*)", text, re.M).group(1)
    for method in ("batch", "mhe", "jekf", "ekf", "fullfield"):
        assert method in entry, method
    assert _screen_lines(text) <= MAX_LINES


def _metavars(name: str, parser: argparse.ArgumentParser) -> dict[str, str]:
    fmt = parser._get_formatter()
    out = {}
    for a in parser._actions:
        if a.nargs == 0 or not a.option_strings or a.help == argparse.SUPPRESS:
            continue
        shown = fmt._format_args(a, fmt._get_default_metavar_for_optional(a))
        for o in a.option_strings:
            if o.startswith("--"):
                out[o] = shown
    return out


def test_one_metavar_per_option_everywhere():
    seen: dict[str, dict[str, str]] = {}
    for name, parser in _commands().items():
        for option, shown in _metavars(name, parser).items():
            seen.setdefault(option, {})[name] = shown
    differ = {o: d for o, d in seen.items() if len(set(d.values())) > 1}
    assert not differ
    assert seen["--mesh"]["identify"] == seen["--mesh"]["calibrate"] == seen["--mesh"]["morph"] == "NXxNY"
    assert seen["--out"]["identify"] == "DIR"


def test_help_all_shows_the_advanced_options(capsys):
    parser = build_parser()
    short = _commands()["identify"].format_help()
    assert "--qp-solver" not in short and "--pressure-bounds" not in short
    with pytest.raises(SystemExit) as exc:
        parser.parse_args(["identify", "--help-all"])
    assert exc.value.code == 0
    full = capsys.readouterr().out
    for option in ("--qp-solver", "--pressure-bounds", "--state-prior", "--same-mesh", "--poll", "--load"):
        assert option in full, option
    # every option of identify is in one of the two
    everything = set(_commands()["identify"]._option_string_actions)
    hidden = {"--backend"}  # a deprecated spelling
    missing = {o for o in everything - hidden if o.startswith("--") and o not in full}
    assert not missing


def test_every_command_with_advanced_options_has_help_all():
    for name, parser in _commands().items():
        if any(hasattr(a, "full_help") for a in parser._actions):
            assert "--help-all" in parser._option_string_actions, name


def test_advanced_options_still_parse():
    args = build_parser().parse_args(
        ["identify", "membrane", "--load", "L1", "--out", "x", "--qp-solver", "osqp", "--poll", "0.1"]
    )
    assert args.qp_solver == "osqp" and args.poll == 0.1


def test_method_help_says_what_each_choice_is():
    text = " ".join(_commands()["identify"].format_help().split())
    assert "fullfield (DIC full field)" in text
    assert "alias realistic" in text
