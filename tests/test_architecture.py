"""The layering rules of docs/architecture.md, enforced on the import graph of the package.

Every ``import`` and ``from ... import`` of a ``wingopt`` module counts, at module level or inside
a function (a lazy import hides a cycle, it does not remove it), and so does
``importlib.import_module("wingopt...")`` (or ``__import__``) with a string literal; imports under
``if TYPE_CHECKING:`` are type hints only and do not count.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import wingopt

ROOT = Path(wingopt.__file__).parent

ENGINES = ("wingopt.control", "wingopt.estimation", "wingopt.design")
"""Engines compute; they do not read problem files, write results, draw, or parse arguments."""
FORBIDDEN_FOR_ENGINES = ("wingopt.results", "wingopt.plots", "wingopt.problem", "wingopt.cli", "wingopt.workflows")
PROBLEM_TYPES = ("wingopt.problem.membrane",)
"""The problem dataclasses an engine may name (a design's sensor specs): types, not the loader
(``wingopt.problem``), the table reader (``problem.fields``) or the problem-file text."""
LAYERS_BELOW_ENGINES = {"wingopt.optim": ("wingopt.control", "wingopt.estimation", *FORBIDDEN_FOR_ENGINES)}
"""The optimisation layer serves the engines: it imports none of them (nor anything above)."""
MAX_LINES = 400
"""Modules of the engines and of optim/ own one idea each; none is longer than this."""


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _type_checking_lines(tree: ast.AST) -> set[int]:
    lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for sub in node.body:
                lines.update(range(sub.lineno, (sub.end_lineno or sub.lineno) + 1))
    return lines


_IMPORT_CALLS = ("importlib.import_module", "import_module", "__import__")


def _literal_import(node: ast.AST) -> str | None:
    """The module of ``importlib.import_module("wingopt...")`` (or ``__import__``) with a string literal."""
    if not (isinstance(node, ast.Call) and node.args and ast.unparse(node.func) in _IMPORT_CALLS):
        return None
    arg = node.args[0]
    return arg.value if isinstance(arg, ast.Constant) and isinstance(arg.value, str) else None


def _imports(path: Path, modules: set[str], me: str | None = None) -> set[str]:
    """``wingopt`` modules imported by ``path`` (resolved to the module files that exist)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skip = _type_checking_lines(tree)
    me = _module_name(path) if me is None else me
    package = me if path.name == "__init__.py" else me.rsplit(".", 1)[0]
    out: set[str] = set()
    for node in ast.walk(tree):
        if getattr(node, "lineno", None) in skip:
            continue
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(
                    package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else [])
                )
            names = [base] + [f"{base}.{a.name}" for a in node.names]
        elif (literal := _literal_import(node)) is not None:
            names = [literal]
        for name in names:
            if not name.startswith("wingopt"):
                continue
            # the longest existing module that the name starts with
            while name and name not in modules:
                name = name.rsplit(".", 1)[0] if "." in name else ""
            if name and name != me:
                out.add(name)
    return out


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    files = sorted(ROOT.rglob("*.py"))
    modules = {_module_name(p) for p in files}
    return {_module_name(p): _imports(p, modules) for p in files}


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def _package(module: str) -> str:
    parts = module.split(".")
    return ".".join(parts[:2])


def _is_package_init(module: str) -> bool:
    return (ROOT.parent / Path(*module.split(".")) / "__init__.py").exists()


def test_the_graph_is_read(graph):
    # A reader that found nothing would pass every rule below.
    assert len(graph) > 60
    assert "wingopt.dynamics.modes" in graph["wingopt.dynamics.statespace"]
    assert "wingopt.estimation.mhe.settings" in graph["wingopt.estimation.mhe.estimator"]
    assert "wingopt.design.montecarlo" in graph["wingopt.design.rerank"]
    assert "wingopt.estimation.runners" in graph["wingopt.design.montecarlo"]


def test_no_cycles_between_files(graph):
    # A package's __init__ re-exports its modules; the edges *into* an __init__ from its own
    # submodules would be the cycle "package imports module imports package" that Python resolves
    # only by import order. Such imports are forbidden too: they are reported here as cycles.
    assert _cycles(graph) == []


def test_no_cycles_between_packages(graph):
    edges: dict[str, set[str]] = {}
    for mod, deps in graph.items():
        src = _package(mod)
        for d in deps:
            dst = _package(d)
            if dst != src:
                edges.setdefault(src, set()).add(dst)
    assert _cycles(edges) == []


RULES = {**{engine: FORBIDDEN_FOR_ENGINES for engine in ENGINES}, **LAYERS_BELOW_ENGINES}
"""Layer -> the layers it must not import."""
ALLOWED = {engine: PROBLEM_TYPES for engine in ENGINES}
"""Layer -> the modules it may import although they lie in a forbidden layer."""


def _within(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


def _violations(graph: dict[str, set[str]], layer: str) -> list[str]:
    return sorted(
        f"{mod} -> {d}"
        for mod, deps in graph.items()
        if _within(mod, layer)
        for d in deps
        if any(_within(d, f) for f in RULES[layer]) and d not in ALLOWED.get(layer, ())
    )


@pytest.mark.parametrize("layer", sorted(RULES))
def test_layers_do_not_import_what_they_must_not(graph, layer):
    assert _violations(graph, layer) == []


ENGINES_DO_NOT_USE = ("matplotlib", "tomllib")
"""Engines draw nothing and read no TOML (problem files): the libraries of both are the plots' and the loader's."""


@pytest.mark.parametrize("engine", ENGINES)
def test_engines_neither_draw_nor_read_problem_files(engine):
    bad = []
    for path in (ROOT / engine.split(".")[1]).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            names += [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else []
            bad += [f"{path.relative_to(ROOT)}: {n}" for n in names if n.split(".")[0] in ENGINES_DO_NOT_USE]
    assert bad == []


def test_every_module_is_small():
    """Small modules that each own one idea: none of the package is longer than MAX_LINES."""
    long = {
        str(p.relative_to(ROOT)): n for p in ROOT.rglob("*.py") if (n := len(p.read_text().splitlines())) > MAX_LINES
    }
    assert long == {}


IMPORTLIB_ALLOWED = {"wingopt", "wingopt.cli"}
"""The lazy top-level exports and the command discovery; every other import is a statement."""


def test_no_module_imports_by_a_name_built_at_run_time():
    # importlib.import_module("wingopt." + name) is an edge the graph above cannot see.
    users = {
        _module_name(p)
        for p in ROOT.rglob("*.py")
        if any(
            getattr(node, "attr", getattr(node, "id", None)) in ("import_module", "__import__")
            for node in ast.walk(ast.parse(p.read_text(encoding="utf-8")))
            if isinstance(node, (ast.Attribute, ast.Name))
        )
    }
    assert users <= IMPORTLIB_ALLOWED


def test_the_rules_catch_a_violation(tmp_path):
    # The cycle finder and the reader on a made-up package: a -> b -> a, and a TYPE_CHECKING import ignored.
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [["a", "b"]]
    src = tmp_path / "m.py"
    src.write_text(
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    import wingopt.plots\n"
        "def f():\n    import wingopt.cli\n"
    )
    tree = ast.parse(src.read_text())
    assert _type_checking_lines(tree) == {3}
    # A lazy import and an importlib call with a literal are edges; an engine naming the loader, a
    # plot or a workflow through them is caught, a problem dataclass is allowed.
    src.write_text(
        src.read_text()
        + "import importlib\n"
        + "def g(name):\n"
        + "    importlib.import_module('wingopt.workflows.design')\n"
        + "    __import__('wingopt.plots.design')\n"
        + "    importlib.import_module(name)\n"
        + "    from wingopt.problem import load_problem\n"
        + "    from wingopt.problem.membrane import StretchSensorSpec\n"
    )
    modules = {_module_name(p) for p in ROOT.rglob("*.py")}
    edges = _imports(src, modules, me="wingopt.design.fake")
    assert edges == {
        "wingopt.cli",
        "wingopt.workflows.design",
        "wingopt.plots.design",
        "wingopt.problem",
        "wingopt.problem.membrane",
    }
    assert _violations({"wingopt.design.fake": edges}, "wingopt.design") == [
        "wingopt.design.fake -> wingopt.cli",
        "wingopt.design.fake -> wingopt.plots.design",
        "wingopt.design.fake -> wingopt.problem",
        "wingopt.design.fake -> wingopt.workflows.design",
    ]
