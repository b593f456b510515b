"""Problem files: TOML descriptions of a wing, validated into frozen dataclasses.

``load_problem("membrane")`` reads the built-in ``problems/membrane.toml``; any path works too.
"""

from __future__ import annotations

import importlib.util
import re
import tomllib
from pathlib import Path
from typing import Any

from wingopt.errors import InputError, ProblemFileError
from wingopt.problem import membrane, plate
from wingopt.problem.fields import Table
from wingopt.problem.membrane import MembraneProblem

__all__ = [
    "load_problem",
    "as_problem",
    "read_problem_table",
    "parse_problem",
    "parse_mesh",
    "builtin_problems",
    "PROBLEMS_DIR",
    "MembraneProblem",
]


def _problems_dir() -> Path:
    # Installed: the repository's top-level problems/ is the package ``wingopt._problems`` (setup.py
    # maps it, nothing is copied). From a source checkout on PYTHONPATH that package does not exist.
    try:
        spec = importlib.util.find_spec("wingopt._problems")
    except ImportError:
        spec = None
    if spec is not None and spec.submodule_search_locations:
        return Path(next(iter(spec.submodule_search_locations)))
    return Path(__file__).resolve().parents[2] / "problems"


PROBLEMS_DIR = _problems_dir()
"""Directory of the built-in problem files (``wingopt._problems`` installed; ``problems/`` in a checkout)."""

_KINDS = {"membrane": membrane.from_table, "plate": plate.from_table}
"""Problem kind -> ``from_table(root: Table, name: str)`` of its schema."""


def builtin_problems() -> list[str]:
    """Names of the built-in problem files."""
    return sorted(p.stem for p in PROBLEMS_DIR.glob("*.toml"))


def _resolve(problem: str | Path) -> Path:
    if isinstance(problem, bytes) or not isinstance(problem, (str, Path)) or not str(problem).strip():
        raise ProblemFileError(
            f"problem = {problem!r}: expected a problem file (.toml) path or a built-in name "
            f"({', '.join(builtin_problems())})"
        )
    if "\0" in str(problem):
        raise ProblemFileError(f"problem = {problem!r}: not a file name (holds a NUL character)")
    path = Path(problem)
    if path.suffix == ".toml" or path.exists():
        if path.is_dir():
            raise ProblemFileError(f"problem = {str(problem)!r}: is a directory, expected a .toml file")
        if path.exists() and not path.is_file():
            raise ProblemFileError(f"problem = {str(problem)!r}: not a regular file (a device, a pipe)")
        if not path.is_file():
            raise ProblemFileError(f"problem = {str(problem)!r}: no such file")
        return path
    builtin = PROBLEMS_DIR / f"{problem}.toml"
    if builtin.is_file():
        return builtin
    names = ", ".join(builtin_problems()) or "none found"
    raise ProblemFileError(f"problem = {str(problem)!r}: expected a .toml file or a built-in name ({names})")


def as_problem(problem, kind: str | None = None, name: str = "problem"):
    """A loaded problem of ``kind`` (a path or built-in name is loaded); an :class:`InputError` naming
    ``name`` for anything else (``None``, a dict, a problem of another kind)."""
    if isinstance(problem, (str, Path)):
        problem = load_problem(problem)
    got = getattr(problem, "kind", None)
    if got not in _KINDS or not hasattr(problem, "nodes"):
        raise InputError(
            f"{name} = {type(problem).__name__}: expected a problem from wingopt.load_problem (or its file or name)"
        )
    if kind is not None and got != kind:
        raise InputError(f"{name}: expected a {kind} problem, got a {got} problem ({getattr(problem, 'name', '')!r})")
    return problem


def parse_problem(data: dict[str, Any], source: str = "<memory>", name: str = "problem"):
    """Validate a parsed TOML document into a problem dataclass."""
    root = Table(data, source)
    kind = root.string("kind", choices=tuple(_KINDS))
    return _KINDS[kind](root, name)


def load_problem(problem: str | Path):
    """Read and validate a problem file (path or built-in name).

    Parameters
    ----------
    problem : str or Path
        A built-in name (``"membrane"``, ``"plate"``: the files shipped in the package) or the
        path of a TOML file of the same schema.

    Returns
    -------
    MembraneProblem or PlateProblem
        The validated, frozen problem (units SI). Unknown keys and non-physical values raise a
        :class:`~wingopt.errors.ProblemFileError` naming the field.
    """
    path = _resolve(problem)
    return parse_problem(_read(path), str(path), path.stem)


def read_problem_table(problem: str | Path) -> dict[str, Any]:
    """The parsed TOML of a problem file (path or built-in name), not validated: the tables as written."""
    return _read(_resolve(problem))


def _read(path: Path) -> dict[str, Any]:
    from wingopt.resources import check_input_file

    try:
        check_input_file(path, "problem")
    except InputError as exc:
        raise ProblemFileError(str(exc)) from None
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ProblemFileError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise ProblemFileError(f"{path}: not a UTF-8 text file (byte {exc.start}): TOML files are UTF-8") from None
    except RecursionError:
        raise ProblemFileError(f"{path}: nested too deeply to be a problem file") from None
    except OSError as exc:
        raise ProblemFileError(f"{path}: cannot read: {exc.strerror}") from None


def parse_mesh(text: str) -> tuple[int, int]:
    """Parse a mesh given as text.

    Parameters
    ----------
    text : str
        ``"NXxNY"``, nodes in x and y, e.g. ``"25x13"``.

    Returns
    -------
    tuple of int
        ``(nx, ny)``.
    """
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", str(text))
    if not m:
        raise InputError(f"mesh = {text!r}: expected NXxNY, nodes in x and y, e.g. 25x13")
    nx, ny = int(m.group(1)), int(m.group(2))
    if nx < 4 or ny < 4:
        raise InputError(f"mesh = {text!r}: expected at least 4 nodes (3 elements) per direction")
    return nx, ny
