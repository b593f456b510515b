"""The code in README.md and docs/*.md runs, and every ``wingopt`` command line in them parses.

Python blocks (fences ``python``) are run, each in a fresh namespace, from a scratch directory
that sees the repository's ``examples/`` and ``problems/`` (so relative paths resolve and written
outputs land in the scratch directory). An HTML comment on the line just above a fence marks it
(invisible on the rendered page):

* ``<!-- snippet: slow -->``: runs only in the slow suite (``pytest -m slow``), e.g. a block that
  morphs the 13x61 plate or fits the FvK membrane;
* ``<!-- snippet: fragment uses=model,measurements -->``: an API outline that continues the page's
  context: it is compiled, not run, and every name it reads must be defined in it, imported, a
  builtin, or declared in ``uses=`` (the context the page gives it). A block without a marker
  must run as it is: no undefined names.

Shell blocks (``sh``, ``bash``, ``console``, ``shell``) and inline code spans: every ``wingopt ...``
command line (``.venv/bin/wingopt``, ``python -m wingopt`` too) is parsed by the CLI's own parser
without running it, so no page shows an option that does not exist or an old spelling.
"""

from __future__ import annotations

import ast
import builtins
import os
import re
import shlex
import warnings
from pathlib import Path

import pytest

from wingopt.cli import build_parser
from wingopt.cli.options import DeprecatedOptionWarning

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(
    r"^(?P<marker><!--\s*snippet:(?P<spec>[^>]*)-->\s*\n)?```(?P<lang>[\w-]*)[^\n]*\n(?P<body>.*?)^```", re.M | re.S
)
SHELL = {"sh", "bash", "console", "shell"}
COMMAND = re.compile(r"(?:^|[\s|;(])(?:\S*/)?(?:wingopt|python -m wingopt)\s+(?P<args>[^\n#]*)")
HISTORIC = ("git archive ce0fdc6",)
"""Lines that run an older wingopt on purpose (docs/studies.md's before/after timing)."""


def _blocks():
    out = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for m in FENCE.finditer(text):
            line = text.count("\n", 0, m.start("body"))
            spec = (m.group("spec") or "").strip()
            out.append((page, line, m.group("lang"), spec, m.group("body")))
    return out


BLOCKS = _blocks()
PYTHON = [b for b in BLOCKS if b[2] == "python"]


def _id(block) -> str:
    return f"{block[0].name}:{block[1]}"


def _free_names(code: str) -> set[str]:
    """Names a block reads that it never binds (a module-level approximation: any binding counts)."""
    tree = ast.parse(code)
    bound, read = set(), set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            (bound if isinstance(node.ctx, (ast.Store, ast.Del)) else read).add(node.id)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            bound.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef, ast.AsyncFunctionDef)):
            bound.add(node.name)
        elif isinstance(node, ast.arg):
            bound.add(node.arg)
        elif isinstance(node, ast.ExceptHandler) and node.name:
            bound.add(node.name)
    return read - bound - set(dir(builtins))


def _uses(spec: str) -> set[str]:
    m = re.search(r"uses=(\S+)", spec)
    return set(m.group(1).split(",")) if m else set()


@pytest.mark.parametrize("block", PYTHON, ids=[_id(b) for b in PYTHON])
def test_python_block_has_no_undefined_names(block):
    page, line, _, spec, code = block
    free = _free_names(code)
    missing = free - _uses(spec) if spec.startswith("fragment") else free
    assert not missing, (
        f"{page.name}:{line}: the block reads {sorted(missing)} without defining them; define them in the "
        "block, or mark it '<!-- snippet: fragment uses=... -->' naming the context the page gives it"
    )


def _runnable(slow: bool):
    out = []
    for b in PYTHON:
        kind = b[3].split()[0] if b[3] else ""
        if kind == "fragment":
            continue
        if (kind == "slow") == slow:
            out.append(b)
    return out


@pytest.fixture
def scratch(tmp_path, monkeypatch):
    for name in ("examples", "problems"):
        (tmp_path / name).symlink_to(ROOT / name)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    return tmp_path


def _run(block) -> None:
    page, line, _, _, code = block
    compiled = compile("\n" * line + code, str(page), "exec")  # tracebacks name the page's line
    exec(compiled, {"__name__": "__doc_snippet__"})


FAST_BLOCKS = _runnable(slow=False)
SLOW_BLOCKS = _runnable(slow=True)


@pytest.mark.parametrize("block", FAST_BLOCKS, ids=[_id(b) for b in FAST_BLOCKS])
def test_python_block_runs(block, scratch):
    _run(block)


@pytest.mark.slow
@pytest.mark.parametrize("block", SLOW_BLOCKS, ids=[_id(b) for b in SLOW_BLOCKS])
def test_slow_python_block_runs(block, scratch):
    _run(block)


def test_fragments_compile():
    for page, line, _, spec, code in PYTHON:
        if spec.startswith("fragment"):
            compile(code, f"{page.name}:{line}", "exec")


def _command_lines():
    out = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        shell_text = "\n".join(b[4] for b in BLOCKS if b[0] == page and b[2] in SHELL)
        shell_text = re.sub(r"\\\n\s*", " ", shell_text)  # continuation lines
        spans = [s.replace("\n", " ") for s in re.findall(r"(?<!`)`([^`]+)`(?!`)", text)]
        spans = [s for s in spans if re.match(r"(?:\S*/)?wingopt\s|python -m wingopt\s", s)]
        for source, lines in (("block", shell_text.splitlines()), ("inline", spans)):
            for ln in lines:
                if any(h in ln for h in HISTORIC):
                    continue
                for m in COMMAND.finditer(ln):
                    out.append((page.name, source, m.group("args").strip()))
    return out


COMMAND_LINES = _command_lines()


def test_the_pages_show_command_lines():
    assert len(COMMAND_LINES) > 40  # the scan finds the pages' commands


@pytest.mark.parametrize("where, source, args", COMMAND_LINES, ids=[f"{p}:{a[:60]}" for p, _, a in COMMAND_LINES])
def test_command_line_parses(where, source, args):
    argv = [a for a in shlex.split(args) if a not in ("<", ">", "|")]
    if not argv or argv[0] in ("--help", "-h", "--version"):
        return
    commands = _subcommands()
    if source == "inline":
        # prose mentions a command and some of its options (`identify --data FILE`): the command
        # and every option named must exist (and not be an old spelling); nothing else is required
        if not re.fullmatch(r"[a-z][a-z-]*", argv[0]):
            return  # a placeholder (COMMAND, CMD:), not a command line
        assert argv[0] in commands, f"{where}: `wingopt {args}`: no command {argv[0]!r}"
        known = _options(commands[argv[0]])
        for a in argv[1:]:
            name = a.split("=", 1)[0]
            if name.startswith("--"):
                assert name in known, f"{where}: `wingopt {args}`: {argv[0]} has no option {name}"
        return
    if "--help" in argv or "-h" in argv:
        assert argv[0] in commands, f"{where}: wingopt {args}: no command {argv[0]!r}"
        return
    parser = build_parser()
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecatedOptionWarning)
        try:
            parser.parse_args(argv)
        except SystemExit as exc:
            pytest.fail(f"{where}: 'wingopt {args}' does not parse (exit {exc.code})")
        except DeprecatedOptionWarning as exc:
            pytest.fail(f"{where}: 'wingopt {args}' uses an old spelling: {exc}")


def _options(p) -> set[str]:
    import argparse

    # an advanced option (--help-all shows it, wingopt.cli.helptext.advanced) is an option all the same
    return {s for a in p._actions if a.help != argparse.SUPPRESS or hasattr(a, "full_help") for s in a.option_strings}


def _subcommands() -> dict:
    import argparse

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


@pytest.fixture(autouse=True)
def _quiet_parser_errors(capsys):
    yield
    capsys.readouterr()


def test_markers_are_known():
    for page, line, _, spec, _ in BLOCKS:
        if spec:
            assert spec.split()[0] in ("slow", "fragment"), f"{page.name}:{line}: unknown snippet marker {spec!r}"


os.environ.setdefault("MPLBACKEND", "Agg")
