"""Reading and validating TOML tables field by field, with one-line errors that name the field.

A :class:`Table` wraps one TOML table. Each accessor takes a key out of it, checks type and
range, and returns the value; :meth:`Table.finish` then rejects whatever keys are left, so
that a typo never passes silently. Messages read like::

    problems/membrane.toml: [material] thickness = -0.001: expected a positive number (m)
"""

from __future__ import annotations

import math
from typing import Any

from wingopt.errors import ProblemFileError

__all__ = ["Table", "MISSING"]


class _Missing:
    def __repr__(self) -> str:
        return "MISSING"


MISSING: Any = _Missing()


class Table:
    """One TOML table being validated.

    Parameters
    ----------
    data : dict
        The parsed table.
    source : str
        The file it came from (for messages).
    path : str
        The table's name inside the file, e.g. ``"material"`` or ``"sensors[2]"``.
    """

    def __init__(self, data: Any, source: str, path: str = "") -> None:
        if not isinstance(data, dict):
            raise ProblemFileError(f"{source}: {self._where(path)}expected a table, got {data!r}")
        self._data = dict(data)
        self.source = source
        self.path = path

    @staticmethod
    def _where(path: str) -> str:
        return f"[{path}] " if path else ""

    def error(self, key: str, value: Any, expected: str) -> ProblemFileError:
        """An error naming this table's ``key``, the offending ``value`` and what was expected."""
        text = repr(value)
        if len(text) > 80:  # a 20000-character name: its start says enough
            text = text[:60] + f"... ({len(text)} characters)"
        return ProblemFileError(f"{self.source}: {self._where(self.path)}{key} = {text}: expected {expected}")

    def has(self, key: str) -> bool:
        return key in self._data

    def peek(self, key: str, default: Any = None) -> Any:
        """The raw value of ``key`` without taking it."""
        return self._data.get(key, default)

    def _take(self, key: str, default: Any, expected: str) -> Any:
        if key in self._data:
            return self._data.pop(key)
        if default is MISSING:
            raise ProblemFileError(f"{self.source}: {self._where(self.path)}{key} is missing: expected {expected}")
        return default

    def number(
        self,
        key: str,
        default: Any = MISSING,
        *,
        positive: bool = False,
        nonnegative: bool = False,
        lo: float | None = None,
        hi: float | None = None,
        unit: str = "",
    ) -> float:
        """A finite real number with optional range checks."""
        what = "a positive number" if positive else "a non-negative number" if nonnegative else "a number"
        if lo is not None or hi is not None:
            what = f"a number in [{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}]"
        if unit:
            what += f" ({unit})"
        val = self._take(key, default, what)
        if val is None:
            return val
        if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
            raise self.error(key, val, what)
        bad = (
            (positive and val <= 0)
            or (nonnegative and val < 0)
            or (lo is not None and val < lo)
            or (hi is not None and val > hi)
        )
        if bad:
            raise self.error(key, val, what)
        return float(val)

    def integer(self, key: str, default: Any = MISSING, *, lo: int | None = None) -> int:
        what = "an integer" + (f" >= {lo}" if lo is not None else "")
        val = self._take(key, default, what)
        if isinstance(val, bool) or not isinstance(val, int) or (lo is not None and val < lo):
            raise self.error(key, val, what)
        return val

    def string(self, key: str, default: Any = MISSING, *, choices: tuple[str, ...] | None = None) -> str:
        what = f"one of {', '.join(choices)}" if choices else "a string"
        val = self._take(key, default, what)
        if not isinstance(val, str) or (choices and val not in choices):
            raise self.error(key, val, what)
        return val

    def numbers(self, key: str, length: int | None, default: Any = MISSING, *, positive: bool = False) -> tuple:
        """A list of numbers, of a fixed ``length`` when given."""
        what = f"a list of {length} numbers" if length else "a list of numbers"
        if positive:
            what = what.replace("numbers", "positive numbers")
        val = self._take(key, default, what)
        if val is None:
            return val
        if not isinstance(val, list) or (length is not None and len(val) != length) or not val:
            raise self.error(key, val, what)
        for v in val:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise self.error(key, val, what)
            if positive and v <= 0:
                raise self.error(key, val, what)
        return tuple(float(v) for v in val)

    def integers(self, key: str, length: int, default: Any = MISSING, *, lo: int | None = None) -> tuple:
        what = f"a list of {length} integers" + (f" >= {lo}" if lo is not None else "")
        val = self._take(key, default, what)
        ok = isinstance(val, list) and len(val) == length
        ok = ok and all(isinstance(v, int) and not isinstance(v, bool) for v in val)
        ok = ok and (lo is None or all(v >= lo for v in val))
        if not ok:
            raise self.error(key, val, what)
        return tuple(val)

    def rect(self, key: str, width: float, height: float) -> tuple[float, float, float, float]:
        """``[x0, x1, y0, y1]`` with ``x0 < x1``, ``y0 < y1``, inside ``[0, width] x [0, height]``."""
        r = self.numbers(key, 4)
        x0, x1, y0, y1 = r
        if not (x0 < x1 and y0 < y1):
            raise self.error(key, list(r), "[x0, x1, y0, y1] with x0 < x1 and y0 < y1")
        tol = 1e-12 * max(width, height)
        if x0 < -tol or y0 < -tol or x1 > width + tol or y1 > height + tol:
            raise self.error(key, list(r), f"a rectangle inside the domain [0, {width}] x [0, {height}]")
        return r

    def table(self, key: str, default: Any = MISSING) -> Table:
        val = self._take(key, default, "a table")
        path = f"{self.path}.{key}" if self.path else key
        return Table(val, self.source, path)

    def tables(self, key: str, default: Any = MISSING) -> list[Table]:
        """An array of tables (``[[key]]``)."""
        val = self._take(key, default, f"one or more [[{key}]] tables")
        if not isinstance(val, list) or not all(isinstance(v, dict) for v in val):
            raise self.error(key, val, f"one or more [[{key}]] tables")
        return [Table(v, self.source, f"{key}[{i + 1}]") for i, v in enumerate(val)]

    def finish(self) -> None:
        """Reject any key nobody asked for."""
        if self._data:
            key = next(iter(self._data))
            raise ProblemFileError(
                f"{self.source}: {self._where(self.path)}unknown key {key!r} (value {self._data[key]!r})"
            )
