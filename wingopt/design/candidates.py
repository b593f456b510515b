"""Candidate sensor rectangles: a grid of positions x sizes, user lists and keep-out zones.

Grid candidates lie on the lattice of ``sub`` cells per element (half elements by default: 2.9 mm
on the 25x13 membrane), which makes their information cheap and exact
(:mod:`wingopt.design.information`); sizes are snapped to that lattice. User rectangles may be
anywhere. A keep-out zone removes every candidate that overlaps it.

The ``--candidates`` SPEC is ``;``-separated items:

* ``sizes=WxH,WxH,...`` — sensor sizes in metres (default: the problem's sensor sizes);
* ``step=N`` — grid step in lattice cells (default 1);
* ``keepout=x0:x1:y0:y1`` — a keep-out rectangle (repeatable);
* ``rect=x0:x1:y0:y1`` — an extra candidate (repeatable);
* ``only-rects`` — no grid, only the ``rect`` items (plus the problem's own sensors).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError
from wingopt.problem.membrane import MembraneProblem

__all__ = ["CandidateSet", "candidate_grid", "parse_candidates", "default_sizes"]


@dataclass(frozen=True, eq=False)
class CandidateSet:
    """Rectangles ``(N, 4)`` as ``[x0, x1, y0, y1]`` with a size label per candidate."""

    rects: np.ndarray
    size_index: np.ndarray
    sizes: tuple[tuple[float, float], ...]
    keepout: tuple[tuple[float, float, float, float], ...] = ()

    def __len__(self) -> int:
        return int(self.rects.shape[0])

    def centres(self) -> np.ndarray:
        r = self.rects
        return np.column_stack([(r[:, 0] + r[:, 1]) / 2, (r[:, 2] + r[:, 3]) / 2])

    def find(self, rect, tol: float = 1e-9) -> int | None:
        """Index of a candidate equal to ``rect`` (within ``tol`` m), else ``None``."""
        d = np.max(np.abs(self.rects - np.asarray(rect, dtype=float)[None]), axis=1)
        i = int(np.argmin(d))
        return i if d[i] <= tol else None


def default_sizes(problem: MembraneProblem) -> tuple[tuple[float, float], ...]:
    """The distinct sizes of the problem's sensors (rounded to 0.1 mm)."""
    out = []
    for s in problem.sensors:
        wh = (round(s.rect[1] - s.rect[0], 4), round(s.rect[3] - s.rect[2], 4))
        if wh not in out:
            out.append(wh)
    if not out:
        raise InputError("problem: no [[sensors]] to take candidate sizes from; give sizes=WxH in --candidates")
    return tuple(out)


def _overlaps(rects: np.ndarray, zone) -> np.ndarray:
    x0, x1, y0, y1 = zone
    return (rects[:, 0] < x1) & (rects[:, 1] > x0) & (rects[:, 2] < y1) & (rects[:, 3] > y0)


def candidate_grid(
    problem: MembraneProblem,
    sizes: Sequence[tuple[float, float]] | None = None,
    step: int = 1,
    sub: int = 2,
    keepout: Sequence[tuple[float, float, float, float]] = (),
    extra: Sequence[tuple[float, float, float, float]] = (),
    grid: bool = True,
) -> CandidateSet:
    """Every lattice-aligned rectangle of the given sizes (step ``step`` cells), minus keep-outs."""
    if not (isinstance(step, int) and step >= 1):
        raise InputError(f"step = {step!r}: expected a positive integer (lattice cells)")
    sizes = default_sizes(problem) if sizes is None else tuple(sizes)
    nx, ny = (n - 1 for n in problem.nodes)
    cx, cy = nx * sub, ny * sub
    hx, hy = problem.width / cx, problem.height / cy
    rects, labels = [], []
    for k, (w, h) in enumerate(sizes):
        if not (w > 0 and h > 0):
            raise InputError(f"candidate size {w}x{h}: expected positive width and height (m)")
        iw, ih = max(1, int(round(w / hx))), max(1, int(round(h / hy)))
        if iw > cx or ih > cy:
            raise InputError(f"candidate size {w}x{h}: larger than the membrane {problem.width}x{problem.height}")
        if not grid:
            continue
        for i in range(0, cx - iw + 1, step):
            for j in range(0, cy - ih + 1, step):
                rects.append((i * hx, (i + iw) * hx, j * hy, (j + ih) * hy))
                labels.append(k)
    for r in extra:
        x0, x1, y0, y1 = (float(v) for v in r)
        if not (0 <= x0 < x1 <= problem.width + 1e-12 and 0 <= y0 < y1 <= problem.height + 1e-12):
            raise InputError(f"candidate rect = {list(r)}: expected x0 < x1, y0 < y1 inside the membrane")
        rects.append((x0, x1, y0, y1))
        labels.append(-1)
    R = np.array(rects, dtype=float).reshape(-1, 4)
    lab = np.array(labels, dtype=int)
    keep = np.ones(len(R), dtype=bool)
    for z in keepout:
        keep &= ~_overlaps(R, z)
    if not keep.any():
        raise InputError("candidates: none left after the keep-out zones")
    return CandidateSet(R[keep], lab[keep], tuple(sizes), tuple(tuple(z) for z in keepout))


def _four(text: str, item: str) -> tuple[float, float, float, float]:
    try:
        v = tuple(float(t) for t in text.split(":"))
    except ValueError:
        v = ()
    if len(v) != 4:
        raise InputError(f"--candidates item {item!r}: expected four numbers x0:x1:y0:y1 (m)")
    return v


def parse_candidates(spec: str | None, problem: MembraneProblem, sub: int = 2) -> CandidateSet:
    """Build the candidate set from a ``--candidates`` SPEC (see the module docstring)."""
    sizes, step, keepout, extra, grid = None, 1, [], [], True
    for item in (spec or "").split(";"):
        item = item.strip()
        if not item:
            continue
        key, _, val = item.partition("=")
        if key == "sizes":
            try:
                sizes = [tuple(float(t) for t in s.lower().split("x")) for s in val.split(",")]
            except ValueError:
                sizes = None
            if not sizes or any(len(s) != 2 for s in sizes):
                raise InputError(f"--candidates item {item!r}: expected sizes=WxH[,WxH...] in metres")
        elif key == "step":
            try:
                step = int(val)
            except ValueError:
                raise InputError(f"--candidates item {item!r}: expected step=N (a positive integer)") from None
        elif key == "keepout":
            keepout.append(_four(val, item))
        elif key == "rect":
            extra.append(_four(val, item))
        elif key == "only-rects":
            grid = False
        else:
            raise InputError(f"--candidates item {item!r}: expected sizes=, step=, keepout=, rect= or only-rects")
    if not grid:
        extra = extra + [s.rect for s in problem.sensors]
        if not extra:
            raise InputError("--candidates only-rects: no rect= items and no sensors in the problem")
    return candidate_grid(problem, sizes, step, sub, keepout, extra, grid)


def with_problem_sensors(problem, cands: CandidateSet) -> tuple[CandidateSet, np.ndarray | None]:
    """Append the problem's own sensors (the default layout) unless already candidates."""
    if not problem.sensors:
        return cands, None
    idx, extra = [], []
    for s in problem.sensors:
        i = cands.find(s.rect)
        if i is None:
            extra.append(s.rect)
            idx.append(len(cands) + len(extra) - 1)
        else:
            idx.append(i)
    if extra:
        cands = CandidateSet(
            np.vstack([cands.rects, np.array(extra, dtype=float)]),
            np.concatenate([cands.size_index, -np.ones(len(extra), dtype=int)]),
            cands.sizes,
            cands.keepout,
        )
    return cands, np.array(idx)
