"""Readers of per-frame DIC files: DICe solution files and the plain CSV-per-frame layout.

**DICe** (Sandia's Digital Image Correlation Engine, github.com/dicengine/dice; format from
``src/core/DICe_Schema.cpp``: ``Schema::write_output``, ``Output_Spec::write_info/write_header/
write_frame``; names from ``src/base/DICe_FieldEnums.cpp``; status codes from ``src/base/DICe.h``):

* one file per frame ``<prefix>_<frame>.txt`` (default prefix ``DICe_solution``; the frame number
  zero-padded to the digits of the last frame; ``<prefix>_<frame>.<nproc>.<rank>.txt`` for
  parallel runs, not supported here: merge them first);
* an information block of lines starting with ``***`` (absent when the header goes to a separate
  ``.info`` file), e.g. ``*** Reference image: ...``;
* a header row ``SUBSET_ID<d>NAME<d>NAME...`` (``SUBSET_ID`` absent with ``omit_output_row_id``),
  the delimiter ``<d>`` being ``output_delimiter`` (a space by default, ``,`` in DICe's examples);
* one row per subset, every subset in every frame, values written ``%4.4E`` (5 significant digits).

Columns used: the stereo model coordinates ``MODEL_COORDINATES_X/Y`` (reference positions in the
calibration's world frame and unit, often mm) and ``MODEL_DISPLACEMENT_X/Y/Z`` (required: a
single-camera run has no ``Z``); ``SIGMA`` (required; ``-1`` marks a failed subset);
``STATUS_FLAG`` and ``MATCH`` (optional; ``MATCH = -1`` also marks a subset whose strain could not
be computed); ``VSG_STRAIN_XX/YY/XY`` (optional, all or none). ``COORDINATE_X/Y``,
``DISPLACEMENT_X/Y`` are image pixels and are ignored. DICe's VSG strain is the 2-D Green–Lagrange
strain of the in-plane displacements (``0.5 (2 u_x + u_x^2 + v_x^2)``, ``0.5 (u_y + v_x + u_x u_y +
v_x v_y)``: the tensor component), computed in the model frame: it has no ``w`` terms
(``strain_kind = "inplane"``). DICe files carry no time: ``t = (frame - first) / frame_rate``.

Problems in the input give one-line :class:`~wingopt.errors.DataFileError` s naming the file, or a
logged warning when nothing is lost (missing frames become all-invalid frames, missing points
invalid points, flagged points are dropped and counted by reason).
"""

from __future__ import annotations

import glob as globmod
import logging
import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wingopt.errors import DataFileError, InputError
from wingopt.measurements.dic import STRAIN_REFERENCES, DICFrames, DICMapping, DICReadReport, check_plausible

__all__ = ["read_dice", "read_dic_csv", "DICE_FAILURE_FLAGS", "DICE_REQUIRED"]

log = logging.getLogger(__name__)

DICE_REQUIRED = (
    "MODEL_COORDINATES_X",
    "MODEL_COORDINATES_Y",
    "MODEL_DISPLACEMENT_X",
    "MODEL_DISPLACEMENT_Y",
    "MODEL_DISPLACEMENT_Z",
    "SIGMA",
)
DICE_STRAINS = ("VSG_STRAIN_XX", "VSG_STRAIN_YY", "VSG_STRAIN_XY")
DICE_FAILURE_FLAGS = frozenset({5, 7, 8, 9, 10, 11, 12, 13, 14, 16, 17, 19, 20, 21, 22, 23, 24, 25, 27, 28, 29, 30})
"""DICe ``Status_Flag`` values of a failed or skipped subset (``DICe.h``: INITIALIZE_FAILED = 5,
SEARCH_FAILED = 7, CORRELATION_FAILED = 8, ..., FRAME_SKIPPED = 30)."""
_CSV_REQUIRED = ("x", "y", "u", "v", "w")
_CSV_STRAINS = ("exx", "eyy", "exy")
_KIND_TAG = "wingopt strain kind:"


@dataclass
class _Frame:
    number: int
    path: str
    ids: np.ndarray  # (n,) point identifiers
    X: np.ndarray
    Y: np.ndarray
    data: dict  # u, v, w, exx, eyy, exy -> (n,) in DIC units
    bad: dict  # reason -> (n,) bool
    info: dict  # header facts


def _list_files(source, pattern: str) -> list[Path]:
    if isinstance(source, (list, tuple)):
        files = [Path(p) for p in source]
    elif Path(source).is_dir():
        files = sorted(Path(source).glob(pattern))
    else:
        files = [Path(p) for p in sorted(globmod.glob(str(source)))]
    if not files:
        raise DataFileError(f"{source}: no frame files found (pattern {pattern!r}): expected one file per frame")
    return files


def _name(source) -> str:
    """A source for messages: a path, or a list of files as their folder and count."""
    if isinstance(source, (list, tuple)) and source:
        return f"{Path(source[0]).parent} ({len(source)} files)"
    return str(source)


def _frame_number(path: Path) -> int:
    if re.search(r"_\d+\.\d+\.\d+\.txt$", path.name):
        raise DataFileError(f"{path}: a per-processor DICe file (.<nproc>.<rank>.txt): expected merged frame files")
    m = re.search(r"(\d+)\.[A-Za-z]+$", path.name)
    if not m:
        raise DataFileError(f"{path}: no frame number at the end of the file name: expected <prefix>_<frame>.<ext>")
    return int(m.group(1))


def _read_table(path: Path, comments: tuple[str, ...]) -> tuple[list[str], np.ndarray, list[str]]:
    """Header names, numeric body ``(rows, cols)`` and the comment lines of a delimited text file."""
    try:
        lines = path.read_text(encoding="utf-8", errors="strict").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFileError(f"{path}: cannot be read ({type(exc).__name__}): expected a text file") from None
    i, notes = 0, []
    while i < len(lines) and (not lines[i].strip() or lines[i].lstrip().startswith(comments)):
        notes.append(lines[i])
        i += 1
    if i == len(lines):
        raise DataFileError(f"{path}: no header row: expected a header with column names and one row per point")
    delim = "," if "," in lines[i] else None
    names = [n.strip() for n in lines[i].split(delim)]
    body = [ln for ln in lines[i + 1 :] if ln.strip() and not ln.lstrip().startswith(comments)]
    if not body:
        raise DataFileError(f"{path}: header but no data rows: expected one row per point")
    try:
        data = np.loadtxt(body, delimiter=delim, ndmin=2, dtype=float)
    except ValueError:
        data = _parse_slowly(path, names, body, delim, i + 2)
    if data.shape[1] != len(names):
        raise DataFileError(f"{path}: {data.shape[1]} values per row for {len(names)} header names")
    return names, data, notes


_MISSING = frozenset({"", "nan", "-nan", "na", "n/a", "null", "none"})


def _parse_slowly(path, names, body, delim, first_line) -> np.ndarray:
    """Cell by cell: empty cells and ``nan`` are NaN; the first bad cell raises with its line."""
    rows = []
    for k, ln in enumerate(body):
        cells = [c.strip() for c in ln.split(delim)]
        if len(cells) != len(names):
            raise DataFileError(
                f"{path}:{first_line + k}: {len(cells)} values: expected {len(names)} ({', '.join(names)})"
            )
        row = []
        for name, c in zip(names, cells):
            try:
                row.append(np.nan if c.lower() in _MISSING else float(c))
            except ValueError:
                raise DataFileError(f"{path}:{first_line + k}: {name} = {c!r}: expected a number") from None
        rows.append(row)
    return np.array(rows, dtype=float)


def _need(path, names, required, what) -> None:
    missing = [c for c in required if c not in names]
    if missing:
        raise DataFileError(
            f"{path}: column(s) {', '.join(missing)} missing (found {', '.join(names)}): expected {what}"
        )


def _dice_frame(path: Path) -> _Frame:
    number = _frame_number(path)
    names, data, notes = _read_table(path, ("***",))
    if not any(n.startswith("MODEL_") for n in names) and "DISPLACEMENT_X" in names:
        raise DataFileError(
            f"{path}: no MODEL_DISPLACEMENT_Z (found {', '.join(names)}): expected a stereo DICe run with the "
            "MODEL_COORDINATES_* and MODEL_DISPLACEMENT_* fields in its output_spec (2-D DIC has no deflection)"
        )
    _need(path, names, DICE_REQUIRED, "a DICe stereo solution file with " + ", ".join(DICE_REQUIRED))
    strains = [c for c in DICE_STRAINS if c in names]
    if strains and len(strains) < 3:
        _need(path, names, DICE_STRAINS, "all three VSG_STRAIN_XX, VSG_STRAIN_YY, VSG_STRAIN_XY or none")
    col = {n: data[:, j] for j, n in enumerate(names)}
    ids = col["SUBSET_ID"].astype(np.int64) if "SUBSET_ID" in col else np.arange(data.shape[0])
    keys = ("u", "v", "w") + (("exx", "eyy", "exy") if strains else ())
    src = ("MODEL_DISPLACEMENT_X", "MODEL_DISPLACEMENT_Y", "MODEL_DISPLACEMENT_Z") + tuple(strains)
    bad = {"sigma": col["SIGMA"] < 0}
    if "STATUS_FLAG" in col:
        bad["status_flag"] = np.isin(col["STATUS_FLAG"].astype(np.int64), list(DICE_FAILURE_FLAGS))
    if "MATCH" in col:
        bad["match"] = col["MATCH"] < 0
    info = {"columns": tuple(names)}
    for ln in notes:
        if ln.startswith("*** Reference image:"):
            info["reference"] = ln.split(":", 1)[1].strip()
        if _KIND_TAG in ln:
            info["kind"] = ln.split(_KIND_TAG, 1)[1].strip()
    X, Y = col["MODEL_COORDINATES_X"], col["MODEL_COORDINATES_Y"]
    return _Frame(number, str(path), ids, X, Y, {k: col[s] for k, s in zip(keys, src)}, bad, info)


def _csv_frame(path: Path) -> _Frame:
    number = _frame_number(path)
    names, data, _ = _read_table(path, ("#",))
    names = [n.lower() for n in names]
    _need(path, names, _CSV_REQUIRED, "a header x,y,u,v,w[,exx,eyy,exy][,valid]")
    strains = [c for c in _CSV_STRAINS if c in names]
    if strains and len(strains) < 3:
        _need(path, names, _CSV_STRAINS, "all three exx, eyy, exy or none")
    col = {n: data[:, j] for j, n in enumerate(names)}
    keys = ("u", "v", "w") + tuple(strains)
    bad = {"flagged": col["valid"] == 0} if "valid" in col else {}
    info = {"columns": tuple(names)}
    return _Frame(number, str(path), None, col["x"], col["y"], {k: col[k] for k in keys}, bad, info)


def _match_ids(fr: _Frame, ref: _Frame, tol: float) -> None:
    """Identify a CSV frame's rows with the reference frame's points by their coordinates."""
    q = lambda X, Y: zip(np.round(X / tol).astype(np.int64), np.round(Y / tol).astype(np.int64))  # noqa: E731
    index = {k: i for i, k in enumerate(q(ref.X, ref.Y))}
    fr.ids = np.array([index.get(k, -1 - i) for i, k in enumerate(q(fr.X, fr.Y))], dtype=np.int64)


def _assemble(frames: list[_Frame], frame_rate, mapping, extent, source, ref_kind, kind, units) -> DICFrames:
    rate = _checked_rate(frame_rate, ref_kind)
    ref, nums, step = _ordered(frames)
    all_nums = np.arange(nums[0], nums[-1] + 1, step)
    missing_frames = tuple(int(n) for n in np.setdiff1d(all_nums, nums))
    size = max(np.ptp(ref.X), np.ptp(ref.Y), 1e-300)
    tol = 2e-4 * max(np.abs(ref.X).max(), np.abs(ref.Y).max(), size)
    if ref.ids is None:
        ref.ids = np.arange(ref.X.size)
        for f in frames:
            if f is not ref:
                _match_ids(f, ref, tol)
    pos = {int(i): j for j, i in enumerate(ref.ids)}
    if len(pos) != ref.ids.size:
        raise DataFileError(f"{ref.path}: repeated point ids (or coordinates): expected each point once")
    F, P = all_nums.size, ref.ids.size
    out = {k: np.full((F, P), np.nan) for k in ref.data}
    valid = np.zeros((F, P), dtype=bool)
    dropped, missing_points = Counter(), 0
    for f in frames:
        k = int((f.number - nums[0]) // step)
        missing_points += _place(f, ref, pos, tol, out, valid[k], k, dropped)
    if missing_points:
        dropped["missing"] = missing_points
    dropped = Counter({r: n for r, n in dropped.items() if n})
    notes = []
    if missing_frames:
        notes.append(f"{len(missing_frames)} missing frame(s) kept as all-invalid frames: {list(missing_frames)[:10]}")
        log.warning("%s: %s", source, notes[-1])
    if dropped:
        notes.append("dropped points: " + ", ".join(f"{r} {n}" for r, n in dropped.items()))
        if dropped["missing"] or dropped["nan"]:
            log.warning("%s: %s", source, notes[-1])
    u, v, w = mapping.vectors(out["u"], out["v"], out["w"])
    strains = mapping.strains(out["exx"], out["eyy"], out["exy"]) if "exx" in out else (None, None, None)
    x, y = mapping.points(ref.X, ref.Y)
    report = DICReadReport(source, len(frames), F, P, tuple(dropped.items()), missing_frames, tuple(notes))
    t = (all_nums - all_nums[0]) / rate
    kind = kind if "exx" in out else "none"
    res = DICFrames(x, y, t, u, v, w, *strains, valid, source, units, ref_kind, kind, report)
    check_plausible(res, extent, source)
    return res


def _checked_rate(frame_rate, ref_kind) -> float:
    """The frame rate (Hz) as a positive number, once the strain reference is known too."""
    try:
        rate = float(frame_rate)
    except (TypeError, ValueError):
        rate = float("nan")
    if not (np.isfinite(rate) and rate > 0):
        raise InputError(f"frame_rate = {frame_rate!r}: expected a positive number of frames per second (Hz)")
    if ref_kind not in STRAIN_REFERENCES:
        raise InputError(f"strain_reference = {ref_kind!r}: expected one of {', '.join(STRAIN_REFERENCES)}")
    return rate


def _ordered(frames: list[_Frame]) -> tuple[_Frame, np.ndarray, int]:
    """Sort ``frames`` by number (in place): the grid's frame, the numbers and their step, once every
    frame is known to be one of a series (no repeats, the same columns and reference image, one step)."""
    frames.sort(key=lambda f: f.number)
    nums = np.array([f.number for f in frames])
    dup = np.flatnonzero(np.diff(nums) == 0)
    if dup.size:
        a, b = frames[dup[0]], frames[dup[0] + 1]
        raise DataFileError(f"{b.path}: frame {b.number} also in {a.path}: expected one file per frame")
    ref = max(frames, key=lambda f: f.X.size)  # the grid: the (first) frame with the most points
    for f in frames:
        if f.info["columns"] != ref.info["columns"]:
            raise DataFileError(
                f"{f.path}: columns {', '.join(f.info['columns'])}: expected the same columns as {ref.path}"
            )
        if f.info.get("reference") != ref.info.get("reference"):
            raise DataFileError(
                f"{f.path}: reference image {f.info.get('reference')!r}: expected {ref.info.get('reference')!r} "
                f"as in {ref.path} (a frame from another test?)"
            )
    step = int(Counter(np.diff(nums).tolist()).most_common(1)[0][0]) if nums.size > 1 else 1
    if np.any(np.diff(nums) % step):
        k = int(np.argmax(np.diff(nums) % step)) + 1
        raise DataFileError(
            f"{frames[k].path}: frame {nums[k]} after {nums[k - 1]}: expected frame numbers in steps of {step}"
        )
    return ref, nums, step


def _place(f: _Frame, ref: _Frame, pos: dict, tol: float, out: dict, valid_k: np.ndarray, k: int, dropped) -> int:
    """Put frame ``f``'s points into row ``k`` of ``out`` on the grid of ``ref`` (``valid_k``: the row's
    valid points; ``dropped`` counts the invalid ones by reason); the grid's points ``f`` lacks."""
    cols = np.array([pos.get(int(i), -1) for i in f.ids])
    if np.any(cols < 0) or np.unique(cols).size != cols.size:
        raise DataFileError(
            f"{f.path}: {int(np.sum(cols < 0))} point(s) not in {ref.path} (or repeated): "
            "expected the same grid in every frame (a frame from another test, or a grid that changed?)"
        )
    dev = max(np.abs(f.X - ref.X[cols]).max(), np.abs(f.Y - ref.Y[cols]).max())
    if dev > tol:
        raise DataFileError(
            f"{f.path}: reference coordinates differ from {ref.path} by up to {dev:.4g} (DIC units): "
            "expected the same grid in every frame (a frame from another test, or a grid that changed?)"
        )
    good = np.ones(cols.size, dtype=bool)
    for reason, b in f.bad.items():
        dropped[reason] += int(np.sum(b & good))
        good &= ~b
    finite = np.all([np.isfinite(a) for a in f.data.values()], axis=0)
    dropped["nan"] += int(np.sum(good & ~finite))
    good &= finite
    for key, a in f.data.items():
        out[key][k, cols] = a
    valid_k[cols] = good
    return ref.ids.size - cols.size


def read_dice(
    source,
    frame_rate: float,
    mapping: DICMapping,
    extent: tuple[float, float],
    *,
    prefix: str = "DICe_solution",
    strain_reference: str = "prestrained",
    strain_kind: str | None = None,
) -> DICFrames:
    """Read DICe solution files (a directory, a glob or a list of files) into :class:`DICFrames`.

    Parameters
    ----------
    source : path, glob or sequence of paths
        A directory is searched for ``<prefix>_*.txt``.
    frame_rate : float
        Frames per second (DICe files carry no time).
    mapping : DICMapping
        DIC (model) coordinates -> wing frame; ``mapping.unit`` is the calibration's length unit.
    extent : (W, H)
        The wing's size (m), for the plausibility checks (:func:`~.dic.check_plausible`).
    strain_reference : str
        ``"prestrained"`` when DICe's reference image is the mounted, flat, prestrained membrane.
    strain_kind : str, optional
        Default: ``"inplane"`` (DICe's VSG strain), unless the header says otherwise.
    """
    files = [p for p in _list_files(source, f"{prefix}_*.txt") if not p.name.endswith(".info")]
    frames = [_dice_frame(p) for p in files]
    kind = strain_kind or frames[0].info.get("kind", "inplane")
    return _assemble(frames, frame_rate, mapping, extent, _name(source), strain_reference, kind, mapping.unit)


def read_dic_csv(
    source,
    frame_rate: float,
    extent: tuple[float, float],
    *,
    units: str = "m",
    strain_reference: str = "prestrained",
    strain_kind: str = "surface",
    prefix: str = "frame",
) -> DICFrames:
    """Read the plain CSV-per-frame layout (:mod:`.dic`) in the wing's frame (``units`` m or mm)."""
    files = _list_files(source, f"{prefix}_*.csv")
    mapping = DICMapping(unit=units)
    frames = [_csv_frame(p) for p in files]
    return _assemble(frames, frame_rate, mapping, extent, _name(source), strain_reference, strain_kind, units)
