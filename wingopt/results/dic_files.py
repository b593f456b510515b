"""Writers of DIC frames: the plain NPZ layout, plain CSV frames and DICe solution files (each file atomic).

The layouts are described in :mod:`wingopt.measurements.dic` (NPZ, CSV) and
:mod:`wingopt.measurements.dic_readers` (DICe); the readers there read back what is written here.
Used for round trips, examples (the tunnel stand-in's frame set) and synthetic test data.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from wingopt.errors import OutputError
from wingopt.measurements.dic import DICFrames, DICMapping
from wingopt.results.writer import write_atomic

__all__ = ["write_dic_npz", "write_dic_csv", "write_dice", "DICE_COLUMNS"]

log = logging.getLogger(__name__)


def _write(path: Path, fill) -> Path:
    try:
        return write_atomic(path, fill)
    except OSError as exc:
        raise OutputError(f"{path}: cannot write it ({exc.strerror or exc}): expected a writable location") from None


def _text(path: Path, text: str) -> Path:
    return _write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def write_dic_npz(
    frames: DICFrames, path: str | Path, quantum: dict[str, float] | None = None, extra: dict | None = None
) -> Path:
    """Write ``frames`` in the plain NPZ layout (metres, compressed), atomically.

    ``quantum`` (optional): per field (``"u"``, ``"w"``, ``"exx"``, ...) a step; the field is then
    stored as integers of that step (``<field>_quantum`` beside it), invalid points as 0 — a
    compact file for data whose noise is well above the step. ``extra``: more named arrays stored
    beside (a synthetic record's truth); the readers ignore names they do not know.
    """
    p = Path(path)
    if not p.parent.is_dir():
        raise OutputError(f"{p}: directory {p.parent} does not exist: expected an existing directory")
    arrays = {k: getattr(frames, k) for k in ("t", "x", "y", "u", "v", "w")}
    arrays["valid"] = frames.valid
    if frames.strain_kind != "none":
        arrays.update(exx=frames.exx, eyy=frames.eyy, exy=frames.exy)
    for k, q in (quantum or {}).items():
        if k not in arrays or k in ("t", "x", "y", "valid") or not q > 0:
            raise OutputError(f"quantum[{k!r}] = {q!r}: expected a positive step of one of u, v, w, exx, eyy, exy")
        a = np.where(frames.valid, arrays[k], 0.0) / q
        if np.abs(a).max() >= 2**31:
            raise OutputError(f"quantum[{k!r}] = {q!r}: values up to {np.abs(a).max() * q:.3g} overflow int32")
        arrays[k] = np.round(a).astype(np.int32 if np.abs(a).max() >= 2**15 else np.int16)
        arrays[f"{k}_quantum"] = np.array(float(q))
    meta = {"units": "m", "strain_reference": frames.strain_reference, "strain_kind": frames.strain_kind}
    meta["source"] = frames.source
    clash = sorted(set(extra or {}) & (set(arrays) | set(meta)))
    if clash:
        raise OutputError(f"extra = {clash}: expected names other than the layout's own")
    meta.update(extra or {})

    def fill(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays, **{k: np.array(v) for k, v in meta.items()})

    return _write(p, fill)


def write_dic_csv(frames: DICFrames, directory, *, prefix: str = "frame", first_frame: int = 0) -> list[Path]:
    """Write the plain CSV layout (one file per frame, metres, header ``x,y,u,v,w,exx,eyy,exy,valid``)."""
    d = Path(directory)
    names = ["x", "y", "u", "v", "w"] + (["exx", "eyy", "exy"] if frames.strain_kind != "none" else []) + ["valid"]
    digits = len(str(first_frame + frames.n_frames))
    paths = []
    for k in range(frames.n_frames):
        cols = [frames.x, frames.y] + [getattr(frames, n)[k] for n in names[2:-1]] + [frames.valid[k].astype(float)]
        body = "".join(",".join(f"{c:.9g}" for c in row) + "\n" for row in np.column_stack(cols))
        path = d / f"{prefix}_{first_frame + k:0{digits}d}.csv"
        paths.append(_text(path, f"# {frames.source}, t = {frames.t[k]:.9g} s\n" + ",".join(names) + "\n" + body))
    return paths


DICE_COLUMNS = (
    "SUBSET_ID",
    "COORDINATE_X",
    "COORDINATE_Y",
    "DISPLACEMENT_X",
    "DISPLACEMENT_Y",
    "MODEL_COORDINATES_X",
    "MODEL_COORDINATES_Y",
    "MODEL_COORDINATES_Z",
    "MODEL_DISPLACEMENT_X",
    "MODEL_DISPLACEMENT_Y",
    "MODEL_DISPLACEMENT_Z",
    "VSG_STRAIN_XX",
    "VSG_STRAIN_YY",
    "VSG_STRAIN_XY",
    "SIGMA",
    "GAMMA",
    "MATCH",
    "STATUS_FLAG",
)
"""The columns :func:`write_dice` writes: those of a stereo DICe run with VSG strains."""


def write_dice(
    frames: DICFrames,
    directory,
    mapping: DICMapping | None = None,
    *,
    prefix: str = "DICe_solution",
    first_frame: int = 0,
    pixel_size: float = 1e-4,
    delimiter: str = ",",
    frames_to_write: range | None = None,
) -> list[Path]:
    """Write ``frames`` as DICe solution files ``<prefix>_<frame>.txt`` (one per frame, atomically).

    The layout follows DICe's writer (``***`` information block, header row, ``%4.4E`` values);
    the model coordinates and displacements are in ``mapping``'s frame and unit (default: the
    wing's frame in mm), the pixel columns are nominal (``pixel_size`` m per pixel, no lens model).
    Invalid points are written as DICe writes failed subsets: ``SIGMA = MATCH = GAMMA = -1``,
    ``STATUS_FLAG = 8`` (CORRELATION_FAILED), zero values. The strains go to the VSG columns with
    a header line ``*** wingopt strain kind: <kind>`` that :func:`~wingopt.measurements.dic_readers.read_dice`
    honours (DICe's own VSG strains are in-plane only). ``frames_to_write``: a range of frame
    indices (default all).
    """
    mapping = DICMapping(unit="mm") if mapping is None else mapping
    d = Path(directory)
    X, Y = mapping.inverse_points(frames.x, frames.y)
    v = frames.valid
    U, V, W = (np.where(v, a, 0.0) for a in mapping.inverse_vectors(frames.u, frames.v, frames.w))
    if frames.strain_kind != "none":
        E = [np.where(v, a, 0.0) for a in mapping.inverse_strains(frames.exx, frames.eyy, frames.exy)]
    else:
        E = [np.zeros_like(U)] * 3
    px = mapping.scale / pixel_size
    F, P = U.shape
    digits = len(str(first_frame + F))
    fmt = delimiter.join(["%d"] + ["%.4E"] * (len(DICE_COLUMNS) - 1)) + "\n"
    head = (
        "***\n*** Digital Image Correlation Engine (DICe) solution format, written by wingopt (synthetic frames)\n***\n"
        f"*** Reference image: {frames.source or 'reference'} (reference)\n"
        "*** DIC method : local \n"
        f"*** wingopt strain kind: {frames.strain_kind}\n"
        "*** Coordinates given with (0,0) as upper left corner of image, x positive right, y positive down\n***\n"
        + delimiter.join(DICE_COLUMNS)
        + "\n"
    )
    ids = np.arange(P)
    paths = []
    for k in range(F) if frames_to_write is None else frames_to_write:
        ok = v[k]
        cols = np.column_stack(
            [
                ids,
                X * px,
                Y * px,
                U[k] * px,
                V[k] * px,
                X,
                Y,
                np.zeros(P),
                U[k],
                V[k],
                W[k],
                E[0][k],
                E[1][k],
                E[2][k],
                np.where(ok, 5e-3, -1.0),
                np.where(ok, 1e-3, -1.0),
                np.where(ok, 0.0, -1.0),
                np.where(ok, 0.0, 8.0),
            ]
        )
        body = "".join(fmt % tuple(row) for row in cols)
        paths.append(_text(d / f"{prefix}_{first_frame + k:0{digits}d}.txt", head + body))
    log.debug("wrote %d DICe frame files to %s", len(paths), d)
    return paths
