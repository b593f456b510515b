"""The plain NPZ layout of DIC frames (described in :mod:`.dic`) and :func:`read_dic`, any layout by its path.

A field may be stored compactly as integers with a quantum: an integer array ``w`` beside a
scalar ``w_quantum`` (its unit: metres or mm as ``units`` says, dimensionless for strains) is
read as ``w * w_quantum``; the quantum must be below the noise (the shipped stand-in stores 0.1 µm
and 1e-6 strain against 10 µm and 1e-4 noise). Invalid points may hold any integer there.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from wingopt.errors import DataFileError
from wingopt.measurements.dic import UNITS, DICFrames, DICMapping, DICReadReport, check_plausible
from wingopt.measurements.dic_readers import read_dic_csv, read_dice

__all__ = ["read_dic_npz", "read_dic", "NPZ_REQUIRED", "FIELDS"]

log = logging.getLogger(__name__)

NPZ_REQUIRED = ("t", "x", "y", "u", "v", "w", "valid", "units", "strain_reference")
FIELDS = ("u", "v", "w", "exx", "eyy", "exy")


def _field(data: dict, k: str, name: str) -> np.ndarray:
    """``data[k]`` as floats, decoded with ``data[k + "_quantum"]`` when it is integer-coded."""
    a = np.asarray(data[k])
    q = data.get(f"{k}_quantum")
    if q is None:
        return a.astype(float)
    q = float(np.asarray(q))
    if not (np.issubdtype(a.dtype, np.integer) and np.isfinite(q) and q > 0):
        raise DataFileError(f"{name}: {k}_quantum = {q!r} with {k} of dtype {a.dtype}: expected integers and q > 0")
    return a * q


def read_dic_npz(path: str | Path, extent: tuple[float, float]) -> DICFrames:
    """Read the plain NPZ layout (module docstring of :mod:`.dic`); NaN at valid points is dropped and counted."""
    p, name = Path(path), str(path)
    try:
        with np.load(p, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError) as exc:
        raise DataFileError(f"{name}: cannot be read as an NPZ file ({type(exc).__name__}: {exc})") from None
    missing = [k for k in NPZ_REQUIRED if k not in data]
    strain_keys = [k for k in ("exx", "eyy", "exy") if k in data]
    if strain_keys and len(strain_keys) < 3:
        missing += [k for k in ("exx", "eyy", "exy") if k not in data]
    if missing:
        raise DataFileError(
            f"{name}: array(s) {', '.join(missing)} missing: expected {', '.join(NPZ_REQUIRED)} (+ exx, eyy, exy)"
        )
    units = str(data["units"])
    if units not in UNITS:
        raise DataFileError(f"{name}: units = {units!r}: expected 'm' or 'mm'")
    t = np.asarray(data["t"], float).ravel()
    F, P = t.size, np.asarray(data["x"]).size
    valid = np.asarray(data["valid"])
    if valid.shape != (F, P) or not np.all((valid == 0) | (valid == 1)):
        raise DataFileError(f"{name}: valid has shape {valid.shape}: expected 0/1 or bool of shape ({F}, {P})")
    valid = valid.astype(bool)
    fields = FIELDS[:3] + (FIELDS[3:] if strain_keys else ())
    arrays, nan_count = {}, 0
    for k in fields:
        a = _field(data, k, name)
        if a.shape != (F, P):
            raise DataFileError(f"{name}: {k} has shape {a.shape}: expected ({F}, {P}) (frames, points)")
        bad = valid & ~np.isfinite(a)
        nan_count += int(bad.sum())
        valid &= ~bad
        arrays[k] = a
    for k in fields:  # a point dropped in one field is dropped in all; values there are not used
        arrays[k] = np.where(valid, arrays[k], np.nan)
    s = UNITS[units]
    kind = str(data.get("strain_kind", "surface")) if strain_keys else "none"
    report = DICReadReport(name, 1, F, P, (("nan", nan_count),) if nan_count else ())
    if nan_count:
        log.warning("%s: %d point values are NaN where marked valid: dropped", name, nan_count)
    frames = DICFrames(
        s * np.asarray(data["x"], float).ravel(),
        s * np.asarray(data["y"], float).ravel(),
        t,
        s * arrays["u"],
        s * arrays["v"],
        s * arrays["w"],
        arrays.get("exx"),
        arrays.get("eyy"),
        arrays.get("exy"),
        valid,
        str(data.get("source", name)),
        units,
        str(data["strain_reference"]),
        kind,
        report,
    )
    check_plausible(frames, extent, name)
    return frames


def read_dic(
    source: str | Path,
    extent: tuple[float, float],
    *,
    mapping: DICMapping | None = None,
    frame_rate: float | None = None,
    strain_reference: str = "prestrained",
    strain_kind: str | None = None,
) -> DICFrames:
    """DIC frames from ``source``, whatever its layout: an ``.npz`` file (the plain layout, in the wing's
    frame), a directory (or glob) of DICe solution files ``*.txt``, or of plain CSV frames ``*.csv``.

    ``mapping`` (default: the identity in metres) and ``frame_rate`` (Hz) are needed by the per-frame
    layouts (DICe files carry no time; DICe coordinates are the calibration's); the NPZ layout
    carries both and is refused with a mapping other than the identity in metres, which would
    be ignored.
    """
    src = Path(source)
    mapping = DICMapping() if mapping is None else mapping
    if src.suffix.lower() == ".npz":
        if not src.is_file():
            raise DataFileError(f"{source}: no such file: expected an NPZ file of DIC frames")
        m = mapping
        if (m.origin, m.x_axis, m.y_axis, m.z_axis, m.strain_unit) != ((0.0, 0.0), "+x", "+y", "+z", "strain"):
            raise DataFileError(
                f"{source}: an NPZ file is in the wing's frame and units; the [dic] origin, axes and strain unit "
                "would be ignored: expected them at their defaults (origin [0, 0], axes +x +y +z, strain)"
            )
        return read_dic_npz(src, extent)
    if frame_rate is None:
        raise DataFileError(f"{source}: per-frame DIC files carry no time: expected [dic] frame_rate (Hz)")
    files = sorted(src.glob("*")) if src.is_dir() else []
    txt = [f for f in files if f.suffix == ".txt"]
    csv = [f for f in files if f.suffix == ".csv"]
    if txt and csv:
        raise DataFileError(f"{source}: both .txt (DICe) and .csv frame files: expected one layout per directory")
    if csv:
        return read_dic_csv(
            csv,
            frame_rate,
            extent,
            units=mapping.unit,
            strain_reference=strain_reference,
            strain_kind=strain_kind or "surface",
        )
    return read_dice(
        txt or source, frame_rate, mapping, extent, strain_reference=strain_reference, strain_kind=strain_kind
    )
