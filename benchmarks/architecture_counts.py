"""Count what issue 31 measures of the package's structure: one way in, one core, one physics layer.

Run from the repository root::

    python benchmarks/architecture_counts.py [--json]

Every figure is read from the source (``ast`` and plain text), none is typed in. The
counts are proxies, each stated with how it is measured:

* **route choices**: comparisons with an estimator's or a route's name as a string literal
  (``method == "mhe"``, ``spec.method in ("jekf-seed", ...)``, ``route == "steady"``), by file,
  outside the two modules that own the choice (``estimation/registry.py``: which estimator;
  ``estimation/records.py``: steady or transient);
* **problem.identification reads**: ``.identification`` attribute reads in the engine packages
  (``estimation``, ``control``, ``design``), outside ``estimation/declaration.py``, the one door
  from a problem's ``[identification]`` into estimator settings;
* **membrane internals**: estimation modules importing ``wingopt.membrane.modal``/``.full`` or
  the model classes themselves (the forward-model layer and value types are allowed);
* **Levenberg–Marquardt solvers**: the functions and classes named for Levenberg–Marquardt
  (each iteration loop the package has is one; their wrappers are not);
* **settings fields**: fields of the dataclasses named ``*Settings``, ``*Options`` or ``*Config``;
* **long functions** (> 80 lines), **long modules** (> 400 lines), **repeated opening
  sentences** of module docstrings, **import cycles** (type-only imports included),
  ``# fmt: skip`` lines, and the line counts of the package and of ``estimation/``.
"""

from __future__ import annotations

import argparse
import ast
import importlib.util
import json
import re
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "wingopt"
ENGINES = ("estimation", "control", "design")
# "auto" is left out: it is also the value of a dozen unrelated settings (frame, record, scale)
ESTIMATOR_NAMES = r"(?:mhe|batch|jekf|jekf-seed|jekf-tuned|ekf|fullfield|steady|transient|stream)"
# the two modules that own the choice: the registry (which estimator) and the records (steady or transient)
ROUTE_OWNERS = ("estimation/registry.py", "estimation/records.py")
# the one door from a problem's [identification] into estimator settings
DECLARED_READER = "estimation/declaration.py"
ROUTE_RE = re.compile(rf"(?:==|!=|\bin\b)\s*[\(\[\{{]?\s*[\"']{ESTIMATOR_NAMES}[\"']")
MEMBRANE_INTERNALS = re.compile(
    r"from wingopt\.membrane\.(?:modal|full)\b|import wingopt\.membrane\.(?:modal|full)\b"
    r"|\b(?:FvKModal|BergerModal|FvKMembrane|BergerMembrane)\b"
)
FUNCTION_LIMIT, MODULE_LIMIT = 80, 400


def _files() -> list[Path]:
    return sorted(p for p in ROOT.rglob("*.py") if "__pycache__" not in p.parts)


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _rel(path: Path) -> str:
    return str(path.relative_to(ROOT.parent))


def route_choices(files: list[Path]) -> dict[str, int]:
    out: dict[str, int] = {}
    for p in files:
        if str(p.relative_to(ROOT)) in ROUTE_OWNERS:
            continue
        n = sum(1 for line in p.read_text().splitlines() if ROUTE_RE.search(line) and not line.lstrip().startswith("#"))
        if n:
            out[_rel(p)] = n
    return out


def identification_reads(files: list[Path]) -> dict[str, int]:
    out = {}
    for p in files:
        if p.relative_to(ROOT).parts[0] not in ENGINES or str(p.relative_to(ROOT)) == DECLARED_READER:
            continue
        n = len(re.findall(r"\.identification\b", p.read_text()))
        if n:
            out[_rel(p)] = n
    return out


def membrane_internals(files: list[Path]) -> list[str]:
    return [
        _rel(p)
        for p in files
        if p.relative_to(ROOT).parts[0] == "estimation" and MEMBRANE_INTERNALS.search(p.read_text())
    ]


def _defs(tree: ast.AST):
    return [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))]


def lm_solvers(files: list[Path]) -> list[str]:
    out = []
    for p in files:
        tree = ast.parse(p.read_text())
        for node in _defs(tree):
            if re.search("levenberg", node.name, re.I):
                out.append(f"{_rel(p)}:{node.name}")
    return out


def settings_fields(files: list[Path]) -> dict[str, int]:
    out = {}
    for p in files:
        tree = ast.parse(p.read_text())
        for node in ast.walk(tree):
            if not (isinstance(node, ast.ClassDef) and re.search(r"(Settings|Options|Config)$", node.name)):
                continue
            if not any("dataclass" in ast.unparse(d) for d in node.decorator_list):
                continue
            n = sum(
                1 for s in node.body if isinstance(s, ast.AnnAssign) and "ClassVar" not in ast.unparse(s.annotation)
            )
            out[f"{_rel(p)}:{node.name}"] = n
    return out


def long_functions(files: list[Path]) -> dict[str, int]:
    out = {}
    for p in files:
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > FUNCTION_LIMIT:
                    out[f"{_rel(p)}:{node.name}"] = n
    return out


def long_modules(files: list[Path]) -> dict[str, int]:
    return {_rel(p): n for p in files if (n := len(p.read_text().splitlines())) > MODULE_LIMIT}


def repeated_openings(files: list[Path]) -> list[list[str]]:
    by_sentence = defaultdict(list)
    for p in files:
        doc = ast.get_docstring(ast.parse(p.read_text())) or ""
        first = re.split(r"(?<=[.:])\s", doc.strip(), maxsplit=1)[0].strip().lower()
        if len(first) > 20:
            by_sentence[first].append(_rel(p))
    return [v for v in by_sentence.values() if len(v) > 1]


def _imports(path: Path, modules: set[str]) -> set[str]:
    """Every ``wingopt`` module ``path`` imports, type-only imports included."""
    me = _module(path)
    package = me if path.name == "__init__.py" else me.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            names = [base] + [f"{base}.{a.name}" for a in node.names]
        for name in names:
            while name and name not in modules:
                name = name.rsplit(".", 1)[0] if "." in name else ""
            if name and name != me and name.startswith("wingopt"):
                out.add(name)
    return out


def import_cycles(files: list[Path]) -> list[list[str]]:
    """Strongly connected components of the import graph, type-only imports included (the
    architecture test's Tarjan search, ``tests/test_architecture._cycles``, on this fuller graph)."""
    spec = importlib.util.spec_from_file_location("test_architecture", ROOT.parent / "tests" / "test_architecture.py")
    arch = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(arch)
    modules = {_module(p) for p in files}
    return arch._cycles({_module(p): _imports(p, modules) for p in files})


def lines(files: list[Path], under: str | None = None) -> int:
    return sum(len(p.read_text().splitlines()) for p in files if under is None or p.relative_to(ROOT).parts[0] == under)


def counts() -> dict:
    files = _files()
    routes = route_choices(files)
    reads = identification_reads(files)
    fields = settings_fields(files)
    return {
        "route_choices": {"files": len(routes), "comparisons": sum(routes.values()), "where": routes},
        "identification_reads_in_engines": {"count": sum(reads.values()), "where": reads},
        "estimation_files_importing_membrane_internals": membrane_internals(files),
        "levenberg_marquardt_solvers": lm_solvers(files),
        "settings_fields": {"classes": len(fields), "fields": sum(fields.values()), "where": fields},
        "functions_over_80_lines": long_functions(files),
        "modules_over_400_lines": long_modules(files),
        "repeated_docstring_openings": repeated_openings(files),
        "import_cycles_type_only_included": import_cycles(files),
        "fmt_skip": sum(p.read_text().count("# fmt: skip") for p in files),
        "lines": {"package": lines(files), "estimation": lines(files, "estimation")},
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true", help="print the whole record as JSON")
    args = parser.parse_args(argv)
    c = counts()
    if args.json:
        print(json.dumps(c, indent=1))
        return
    print(
        f"route chosen by string: {c['route_choices']['comparisons']} comparisons"
        f" in {c['route_choices']['files']} files"
    )
    print(f"problem.identification reads in engines: {c['identification_reads_in_engines']['count']}")
    print(f"estimation files importing membrane internals: {len(c['estimation_files_importing_membrane_internals'])}")
    print(f"Levenberg-Marquardt solvers: {len(c['levenberg_marquardt_solvers'])} {c['levenberg_marquardt_solvers']}")
    print(f"settings fields: {c['settings_fields']['fields']} in {c['settings_fields']['classes']} classes")
    longest = sorted(c["functions_over_80_lines"].items(), key=lambda kv: -kv[1])[:5]
    print(f"functions over 80 lines: {len(c['functions_over_80_lines'])} (longest: {longest})")
    print(f"modules over 400 lines: {len(c['modules_over_400_lines'])}")
    print(f"modules opening with another's sentence: {sum(len(g) for g in c['repeated_docstring_openings'])}")
    print(f"import cycles (type-only imports included): {len(c['import_cycles_type_only_included'])}")
    print(f"'# fmt: skip': {c['fmt_skip']}")
    print(f"lines: package {c['lines']['package']}, estimation/ {c['lines']['estimation']}")


if __name__ == "__main__":
    main()
