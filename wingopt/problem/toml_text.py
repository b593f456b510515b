"""Problem-file text: ``[[sensors]]`` tables, and a problem file with new sensors (pure: text out).

The problem file is rebuilt from its parsed tables (:func:`wingopt.problem.read_problem_table`),
keys in their original order, with the ``[[sensors]]`` array replaced; comments are not kept.
:func:`problem_text` is checked by a round trip (``tomllib.loads(problem_text(d, s))`` gives ``d``
with the new sensors). Nothing here reads or writes a file: :mod:`wingopt.results` writes the text.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

from wingopt.errors import InputError

__all__ = ["sensors_text", "problem_text", "table_text"]

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE.match(k) else _string(k)


def _string(s: str) -> str:
    out = s.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n").replace("\t", "\\t")
    out = "".join(c if ord(c) >= 0x20 else f"\\u{ord(c):04x}" for c in out)
    return f'"{out}"'


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    raise InputError(f"TOML value {v!r}: unsupported type {type(v).__name__}")


def _is_table_array(v) -> bool:
    return isinstance(v, list) and len(v) > 0 and all(isinstance(x, dict) for x in v)


def _emit(lines: list[str], table: dict, path: tuple[str, ...]) -> None:
    scalars = [(k, v) for k, v in table.items() if not isinstance(v, dict) and not _is_table_array(v)]
    for k, v in scalars:
        lines.append(f"{_key(k)} = {_value(v)}")
    for k, v in table.items():
        if isinstance(v, dict):
            lines.append("")
            lines.append("[" + ".".join(_key(p) for p in (*path, k)) + "]")
            _emit(lines, v, (*path, k))
        elif _is_table_array(v):
            for item in v:
                lines.append("")
                lines.append("[[" + ".".join(_key(p) for p in (*path, k)) + "]]")
                _emit(lines, item, (*path, k))


def _sensor_tables(rects: Sequence[Sequence[float]], names: Sequence[str] | None, digits: int) -> list[dict]:
    names = names or [f"S{i + 1}" for i in range(len(rects))]
    if len(names) != len(rects):
        raise InputError(f"sensor names: {len(names)} for {len(rects)} rectangles")
    return [{"name": n, "rect": [round(float(v), digits) for v in r]} for n, r in zip(names, rects)]


def sensors_text(rects, names: Sequence[str] | None = None, digits: int = 6, header: str = "") -> str:
    """``[[sensors]]`` tables ready to paste into a problem file (coordinates rounded to ``digits``)."""
    lines = [f"# {h}" for h in header.splitlines()] if header else []
    tables = _sensor_tables(rects, names, digits)
    for t in tables:
        if lines:
            lines.append("")
        lines.append("[[sensors]]")
        lines.append(f"name = {_value(t['name'])}")
        lines.append(f"rect = {_value(t['rect'])}")
    return "\n".join(lines) + "\n"


def problem_text(table: dict, rects, names: Sequence[str] | None = None, digits: int = 6, header: str = "") -> str:
    """The TOML text of ``table`` with its ``[[sensors]]`` replaced by ``rects`` (other keys kept)."""
    new = {}
    placed = False
    for k, v in table.items():
        if k == "sensors":
            new["sensors"] = _sensor_tables(rects, names, digits)
            placed = True
        else:
            new[k] = v
    if not placed:
        new["sensors"] = _sensor_tables(rects, names, digits)
    lines = [f"# {h}" for h in header.splitlines()] if header else []
    _emit(lines, new, ())
    text = "\n".join(lines).strip("\n") + "\n"
    return re.sub(r"\n{3,}", "\n\n", text)


def table_text(table: dict, updates: dict[str, dict] | None = None, header: str = "") -> str:
    """The TOML text of ``table`` with the keys of ``updates`` (``{table name: {key: value}}``) set.

    Other tables and keys are kept in their order; a key set to ``None`` is removed.
    """
    new = {k: (dict(v) if isinstance(v, dict) else v) for k, v in table.items()}
    for name, keys in (updates or {}).items():
        sub = new.setdefault(name, {})
        for k, v in keys.items():
            if v is None:
                sub.pop(k, None)
            else:
                sub[k] = list(v) if isinstance(v, tuple) else v
    lines = [f"# {h}" for h in header.splitlines()] if header else []
    _emit(lines, new, ())
    text = "\n".join(lines).strip("\n") + "\n"
    return re.sub(r"\n{3,}", "\n\n", text)
