"""Every ``wingopt`` import of the benchmark and example scripts resolves (no script is run).

A refactor that moves or removes a public name breaks the scripts under ``benchmarks/`` and
``examples/`` silently: nothing imports them. Here each script is parsed with :mod:`ast` and every
``import wingopt...``, ``from wingopt... import name`` (at module level or inside a function) and
``importlib.import_module("wingopt...")`` with a string literal is checked: the module imports, and
each imported name is an attribute of it or one of its submodules. Fast: the scripts' own code
never runs.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SCRIPTS = sorted((REPO / "benchmarks").glob("*.py")) + sorted((REPO / "examples").glob("*.py"))
_IMPORT_CALLS = ("importlib.import_module", "import_module", "__import__")


def _is_wingopt(module: str | None) -> bool:
    return module is not None and (module == "wingopt" or module.startswith("wingopt."))


def wingopt_imports(path: Path) -> list[tuple[int, str, str | None]]:
    """``(line, module, name)`` of every wingopt import in ``path`` (``name`` None: the module itself)."""
    found: list[tuple[int, str, str | None]] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name, None) for a in node.names if _is_wingopt(a.name)]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and _is_wingopt(node.module):
            found += [(node.lineno, node.module, a.name) for a in node.names]
        elif isinstance(node, ast.Call) and node.args and ast.unparse(node.func) in _IMPORT_CALLS:
            arg = node.args[0]
            if isinstance(arg, ast.Constant) and isinstance(arg.value, str) and _is_wingopt(arg.value):
                found.append((node.lineno, arg.value, None))
    return found


def _resolve(module: str, name: str | None) -> str | None:
    """``None`` if the import resolves, else why not; an optional third-party package that is not
    installed raises ``ModuleNotFoundError`` (the caller skips on it)."""
    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if not _is_wingopt(exc.name):
            raise
        return f"no module {exc.name!r}"
    if name is None or name == "*" or hasattr(mod, name):
        return None
    try:
        importlib.import_module(f"{module}.{name}")
    except ModuleNotFoundError as exc:
        if not _is_wingopt(exc.name):
            raise
        return f"{module!r} has no attribute or submodule {name!r}"
    return None


def test_scripts_are_found():
    names = {p.name for p in SCRIPTS}
    assert len(SCRIPTS) >= 10 and {"bench_jekf.py", "tour.py"} <= names


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_script_wingopt_imports_resolve(path: Path):
    imports = wingopt_imports(path)
    broken, missing_optional = [], []
    for line, module, name in imports:
        what = f"{module}" if name is None else f"{module}.{name}"
        try:
            why = _resolve(module, name)
        except ModuleNotFoundError as exc:  # an optional dependency of the package, not a broken name
            missing_optional.append(f"{what} needs {exc.name}")
            continue
        if why is not None:
            broken.append(f"{path.relative_to(REPO)}:{line}: {what}: {why}")
    assert not broken, "scripts import names the package no longer has:\n" + "\n".join(broken)
    if missing_optional:
        pytest.skip("optional packages not installed: " + "; ".join(missing_optional))


def test_the_checker_sees_broken_imports(tmp_path: Path):
    """The checker itself: a removed module, a removed name and a lazy import are all caught."""
    script = tmp_path / "script.py"
    script.write_text(
        "import wingopt\n"
        "from wingopt.membrane import MembraneModel, no_such_name\n"
        "from wingopt import membrane\n"
        "def f():\n"
        "    from wingopt.no_such_module import x\n"
        "    import wingopt.fe\n",
        encoding="utf-8",
    )
    seen = wingopt_imports(script)
    assert [(m, n) for _, m, n in seen] == [
        ("wingopt", None),
        ("wingopt.membrane", "MembraneModel"),
        ("wingopt.membrane", "no_such_name"),
        ("wingopt", "membrane"),
        ("wingopt.no_such_module", "x"),
        ("wingopt.fe", None),
    ]
    bad = {(m, n) for _, m, n in seen if _resolve(m, n) is not None}
    assert bad == {("wingopt.membrane", "no_such_name"), ("wingopt.no_such_module", "x")}
