"""How a command's ``--help`` reads: one screen (at most 60 lines at 80 columns), details in docs/cli.md.

* :class:`Formatter` — the help layout of every command: option and help on one line where they
  fit, the description and the examples as written (each line under 80 columns).
* :func:`advanced` — an option that ``--help`` leaves out and ``--help-all`` shows (a tuning knob,
  a rarely used override): the everyday options stay on one screen, nothing is hidden for good.
* :func:`add_help_all` — the ``--help-all`` option itself.

tests/test_cli_help.py counts every command's lines and checks that an option has one metavar
in every command.
"""

from __future__ import annotations

import argparse
import textwrap

__all__ = ["Formatter", "advanced", "add_help_all", "MAX_LINES"]

MAX_LINES = 60
"""Most lines of a command's ``--help`` at 80 columns."""


class Formatter(argparse.RawDescriptionHelpFormatter):
    """The help layout of every ``wingopt`` command (the help column at 28: an option with a
    short metavar and its help share a line)."""

    def __init__(self, prog, indent_increment=2, max_help_position=28, width=None):
        super().__init__(prog, indent_increment, max_help_position, width)

    def _fill_text(self, text, width, indent):
        # The description and the examples keep their lines; a line too long for the terminal is
        # wrapped (its continuation indented like it) rather than left to the terminal to break.
        out = []
        for line in text.splitlines():
            lead = " " * (len(line) - len(line.lstrip()))
            if len(indent + line) <= width:
                out.append(indent + line)
            else:
                out.extend(textwrap.wrap(line, width, initial_indent=indent, subsequent_indent=indent + lead + "  "))
        return "\n".join(out)


def advanced(action: argparse.Action) -> argparse.Action:
    """Leave ``action`` out of ``--help`` (``--help-all`` shows it); returns it."""
    action.full_help = action.help  # what --help-all shows
    action.help = argparse.SUPPRESS
    return action


class _HelpAll(argparse.Action):
    """Print the help with the advanced options too, then exit."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        for action in parser._actions:
            if hasattr(action, "full_help"):
                action.help = action.full_help
        parser.usage = None  # the full usage line, every option in it
        parser.print_help()
        parser.exit()


def add_help_all(parser: argparse.ArgumentParser) -> None:
    """``--help-all``: the help with every option (those :func:`advanced` left out of ``--help``)."""
    parser.add_argument("--help-all", action=_HelpAll, help="show every option, the advanced ones too")
