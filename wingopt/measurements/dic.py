"""DIC (digital image correlation) frames: the frame type, the coordinate mapping and the plain layouts.

A DIC system films the membrane and reports, per frame and per tracked point, the displacement
``(U, V, W)`` from the reference image and the Lagrange strains ``(E_xx, E_yy, E_xy)``.
:class:`DICFrames` holds them in the wing's frame (metres, ``x`` chordwise from the leading edge,
``y`` spanwise, ``w`` the deflection), with a validity mask (``False``: the point was flagged bad
or is missing in that frame; its values are not used).

Plain layouts (read by :mod:`.dic_npz` and :func:`~.dic_readers.read_dic_csv`; written by
:func:`~.dic_npz.write_dic_npz` and :func:`~.dic_synth.write_dic_csv`):

* **NPZ**, one file: arrays ``t (F,)``, ``x, y (P,)``, ``u, v, w, exx, eyy, exy (F, P)``,
  ``valid (F, P)`` (bool or 0/1) and the strings ``units`` (``"m"`` or ``"mm"``: coordinates and
  displacements) and ``strain_reference`` (``"prestrained"``: the reference image is the mounted,
  prestrained flat membrane, so strains are load-induced only; ``"unstrained"``); optional
  ``strain_kind`` (``"surface"``, ``"inplane"``) and ``source``. Coordinates are in the wing's frame.
  Strains are dimensionless (``exy`` the tensor component, not the engineering shear).
* **CSV per frame**: a header ``x,y,u,v,w,exx,eyy,exy`` (optional ``valid`` column of 0/1; lines
  starting with ``#`` are comments; an empty cell or ``nan`` is a missing value), one row per
  point, files named ``<prefix>_<frame number>.csv``; times come from the frame numbers and the
  frame rate. Read by :func:`~.dic_readers.read_dic_csv`.

The DICe solution files (Sandia's DIC engine) are read by :func:`~.dic_readers.read_dice`.
Strain kinds: ``"surface"`` is the Lagrange strain of the 3-D surface (VIC-3D's exx, eyy, exy;
``E_xx = u_x + (u_x^2 + v_x^2 + w_x^2)/2``); ``"inplane"`` is the 2-D Green–Lagrange strain of the
in-plane displacements only (DICe's ``VSG_STRAIN_*``: no ``w`` terms, so it misses the
deflection's own stretch); ``"none"``: no strains.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from wingopt.errors import DataFileError, InputError

__all__ = [
    "DICMapping",
    "DICReadReport",
    "DICFrames",
    "check_plausible",
    "STRAIN_REFERENCES",
    "STRAIN_KINDS",
    "STRAIN_UNITS",
    "UNITS",
    "AXES",
    "MAX_STRAIN",
]

log = logging.getLogger(__name__)

STRAIN_REFERENCES = ("prestrained", "unstrained")
STRAIN_KINDS = ("surface", "inplane", "none")
MAX_STRAIN = 0.5
"""Largest plausible Lagrange strain of a membrane wing; larger values are almost surely percent."""
UNITS = {"m": 1.0, "mm": 1.0e-3}
STRAIN_UNITS = {"strain": 1.0, "percent": 1.0e-2}
AXES = {"+x": (1.0, 0.0), "-x": (-1.0, 0.0), "+y": (0.0, 1.0), "-y": (0.0, -1.0)}


def _rotate_tensor(R: np.ndarray, exx, eyy, exy):
    """Components of ``R E R^T`` for the symmetric 2-D tensor ``E`` (arrays broadcast)."""
    E = ((exx, exy), (exy, eyy))

    def comp(i, j):
        return sum(R[i, k] * R[j, m] * np.asarray(E[k][m], float) for k in range(2) for m in range(2))

    return comp(0, 0), comp(1, 1), comp(0, 1)


@dataclass(frozen=True)
class DICMapping:
    """How a DIC system's coordinates map to the wing's frame (a problem file's ``[dic]`` table).

    ``wing = scale * R (dic - origin)``: ``origin`` is the DIC position (source units) of the wing's
    origin (leading edge at the root, ``x = y = 0``); ``x_axis`` / ``y_axis`` name the DIC axis, with
    its sign, that points along the wing's ``x`` (chord) / ``y`` (span); ``z_axis`` the sign of the
    DIC ``Z`` along the wing's deflection ``w``; ``unit`` the DIC length unit (``"m"``, ``"mm"``);
    ``strain_unit`` ``"strain"`` or ``"percent"``. Strains rotate as tensors, ``E' = R E R^T``.
    """

    origin: tuple[float, float] = (0.0, 0.0)
    x_axis: str = "+x"
    y_axis: str = "+y"
    z_axis: str = "+z"
    unit: str = "m"
    strain_unit: str = "strain"

    def __post_init__(self) -> None:
        o = tuple(self.origin)
        if len(o) != 2 or not all(isinstance(v, (int, float)) and np.isfinite(v) for v in o):
            raise InputError(f"dic origin = {self.origin!r}: expected two finite numbers [x, y] in DIC units")
        object.__setattr__(self, "origin", (float(o[0]), float(o[1])))
        for name, val, allowed in (
            ("x_axis", self.x_axis, AXES),
            ("y_axis", self.y_axis, AXES),
            ("z_axis", self.z_axis, ("+z", "-z")),
            ("unit", self.unit, UNITS),
            ("strain_unit", self.strain_unit, STRAIN_UNITS),
        ):
            if val not in allowed:
                raise InputError(f"dic {name} = {val!r}: expected one of {', '.join(allowed)}")
        if self.x_axis[1] == self.y_axis[1]:
            raise InputError(f"dic x_axis = {self.x_axis!r}, y_axis = {self.y_axis!r}: expected two different DIC axes")

    @classmethod
    def from_dict(cls, table: dict) -> DICMapping:
        """From a problem file's ``[dic]`` table (unknown keys are an error)."""
        known = {"origin", "x_axis", "y_axis", "z_axis", "unit", "strain_unit"}
        extra = sorted(set(table) - known)
        if extra:
            raise InputError(f"dic: unknown key(s) {', '.join(extra)}: expected some of {', '.join(sorted(known))}")
        return cls(**{k: tuple(v) if k == "origin" else v for k, v in table.items()})

    @property
    def scale(self) -> float:
        """Metres per DIC length unit."""
        return UNITS[self.unit]

    @property
    def rotation(self) -> np.ndarray:
        """``R`` (2, 2): rows are the wing's x and y axes in DIC coordinates."""
        return np.array([AXES[self.x_axis], AXES[self.y_axis]])

    @property
    def z_sign(self) -> float:
        return 1.0 if self.z_axis == "+z" else -1.0

    def points(self, X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """DIC reference coordinates -> wing ``x, y`` (m)."""
        R, s = self.rotation, self.scale
        dx, dy = np.asarray(X, float) - self.origin[0], np.asarray(Y, float) - self.origin[1]
        return s * (R[0, 0] * dx + R[0, 1] * dy), s * (R[1, 0] * dx + R[1, 1] * dy)

    def vectors(self, U: np.ndarray, V: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """DIC displacements -> wing ``u, v, w`` (m)."""
        R, s = self.rotation, self.scale
        return s * (R[0, 0] * U + R[0, 1] * V), s * (R[1, 0] * U + R[1, 1] * V), s * self.z_sign * np.asarray(W)

    def strains(self, exx, eyy, exy) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """DIC strain tensor components -> wing components (dimensionless)."""
        f = STRAIN_UNITS[self.strain_unit]
        return tuple(f * c for c in _rotate_tensor(self.rotation, exx, eyy, exy))

    def inverse_points(self, x, y):
        """Wing ``x, y`` (m) -> DIC coordinates (for writers)."""
        R, s = self.rotation, self.scale
        x, y = np.asarray(x, float) / s, np.asarray(y, float) / s
        return R[0, 0] * x + R[1, 0] * y + self.origin[0], R[0, 1] * x + R[1, 1] * y + self.origin[1]

    def inverse_vectors(self, u, v, w):
        R, s = self.rotation, self.scale
        return (R[0, 0] * u + R[1, 0] * v) / s, (R[0, 1] * u + R[1, 1] * v) / s, self.z_sign * np.asarray(w) / s

    def inverse_strains(self, exx, eyy, exy):
        f = STRAIN_UNITS[self.strain_unit]
        return tuple(c / f for c in _rotate_tensor(self.rotation.T, exx, eyy, exy))


@dataclass(frozen=True)
class DICReadReport:
    """What a reader found: files, frames, points, dropped points by reason, missing frames."""

    source: str
    files: int
    frames: int
    points: int
    dropped: tuple[tuple[str, int], ...] = ()
    missing_frames: tuple[int, ...] = ()
    notes: tuple[str, ...] = ()

    @property
    def dropped_total(self) -> int:
        return sum(n for _, n in self.dropped)

    def as_dict(self) -> dict:
        return {
            "source": self.source,
            "files": self.files,
            "frames": self.frames,
            "points": self.points,
            "dropped": dict(self.dropped),
            "dropped_total": self.dropped_total,
            "missing_frames": list(self.missing_frames),
            "notes": list(self.notes),
        }


_FIELDS = ("u", "v", "w", "exx", "eyy", "exy")


@dataclass(frozen=True, eq=False)
class DICFrames:
    """DIC frames in the wing's frame: F frames of P points.

    Parameters
    ----------
    x, y : ndarray (P,)
        Reference coordinates (m): ``x`` chordwise from the leading edge, ``y`` spanwise.
    t : ndarray (F,)
        Frame times (s), strictly increasing.
    u, v, w : ndarray (F, P)
        Displacements from the reference image (m); ``w`` is the deflection.
    exx, eyy, exy : ndarray (F, P) or None
        Lagrange strains (dimensionless, ``exy`` the tensor component); ``None`` if not measured.
    valid : ndarray of bool (F, P)
        ``False`` where a point is flagged bad or missing; values there are ignored (may be NaN).
    source : str
        Where the frames came from.
    units : str
        Length unit of the source (``"m"``, ``"mm"``); the arrays here are always metres.
    strain_reference : {"prestrained", "unstrained"}
        Reference state of the strains (and displacements).
    strain_kind : {"surface", "inplane", "none"}
        See the module docstring.
    report : DICReadReport, optional
        The reader's account (dropped points, missing frames).
    """

    x: np.ndarray
    y: np.ndarray
    t: np.ndarray
    u: np.ndarray
    v: np.ndarray
    w: np.ndarray
    exx: np.ndarray | None
    eyy: np.ndarray | None
    exy: np.ndarray | None
    valid: np.ndarray
    source: str = ""
    units: str = "m"
    strain_reference: str = "prestrained"
    strain_kind: str = "surface"
    report: DICReadReport | None = field(default=None)

    def __post_init__(self) -> None:
        name = self.source or "DIC frames"
        x, y, t = (np.asarray(getattr(self, k), dtype=float) for k in ("x", "y", "t"))
        if x.ndim != 1 or y.shape != x.shape or t.ndim != 1:
            raise InputError(f"{name}: x {x.shape}, y {y.shape}, t {t.shape}: expected x, y of shape (P,) and t (F,)")
        F, P = t.size, x.size
        valid = np.asarray(self.valid)
        if valid.shape != (F, P) or valid.dtype != bool:
            raise InputError(f"{name}: valid has shape {valid.shape} dtype {valid.dtype}: expected bool ({F}, {P})")
        if self.strain_reference not in STRAIN_REFERENCES:
            raise InputError(
                f"{name}: strain_reference = {self.strain_reference!r}: expected one of {STRAIN_REFERENCES}"
            )
        if self.strain_kind not in STRAIN_KINDS:
            raise InputError(f"{name}: strain_kind = {self.strain_kind!r}: expected one of {STRAIN_KINDS}")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
            raise InputError(f"{name}: reference coordinates x, y: expected finite values for every point")
        if F > 1 and np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0)) + 1
            raise InputError(
                f"{name}: t[{k}] = {float(t[k])!r} after {float(t[k - 1])!r}: expected strictly increasing frame times"
            )
        has_strain = self.strain_kind != "none"
        for k in ("x", "y", "t"):
            object.__setattr__(self, k, locals()[k])
        for k in _FIELDS:
            a = getattr(self, k)
            if a is None and k.startswith("e") and not has_strain:
                continue
            a = np.asarray(a, dtype=float)
            if a.shape != (F, P):
                raise InputError(f"{name}: {k} has shape {a.shape}: expected ({F}, {P}) (frames, points)")
            bad = valid & ~np.isfinite(a)
            if bad.any():
                f, p = np.argwhere(bad)[0]
                raise InputError(
                    f"{name}: {k}[frame {f}, point {p}] = {float(a[f, p])!r}: expected a finite value where valid"
                )
            object.__setattr__(self, k, a)
        if not has_strain:
            for k in ("exx", "eyy", "exy"):
                object.__setattr__(self, k, None)

    @property
    def n_frames(self) -> int:
        return self.t.size

    @property
    def n_points(self) -> int:
        return self.x.size

    @property
    def valid_fraction(self) -> float:
        return float(self.valid.mean()) if self.valid.size else 0.0


def check_plausible(frames: DICFrames, extent: tuple[float, float], name: str | None = None) -> None:
    """Raise :class:`DataFileError` unless ``frames`` can be a membrane wing of ``extent = (W, H)`` (m).

    Checks: the points lie in the wing rectangle (2 % margin) and span at least a fifth of it in
    each direction (unit mix-ups: mm read as m, m read as mm, a wrong origin or axes), the
    displacements are below half the wing's height, and the strains below ``MAX_STRAIN`` (percent).
    """
    name = name or frames.source or "DIC frames"
    W, H = (float(v) for v in extent)
    tol = 0.02 * max(W, H)
    x, y = frames.x, frames.y
    lo, hi = (x.min(), y.min()), (x.max(), y.max())
    if lo[0] < -tol or lo[1] < -tol or hi[0] > W + tol or hi[1] > H + tol:
        span = (hi[0] - lo[0], hi[1] - lo[1])
        hint = "check the origin and axes of the DIC mapping"
        if span[0] > 20 * W or span[1] > 20 * H:
            hint = "the coordinates look like mm read as m: declare unit = 'mm' (and the origin in mm)"
        raise DataFileError(
            f"{name}: points span x [{lo[0]:.4g}, {hi[0]:.4g}] m, y [{lo[1]:.4g}, {hi[1]:.4g}] m: "
            f"expected inside the wing [0, {W:g}] x [0, {H:g}] m; {hint}"
        )
    span = (hi[0] - lo[0], hi[1] - lo[1])
    if span[0] < 0.2 * W or span[1] < 0.2 * H:
        hint = "m read as mm? declare unit = 'm'" if 1e3 * span[0] >= 0.2 * W else "too few points for a membrane"
        raise DataFileError(
            f"{name}: points span only {span[0]:.3g} m x {span[1]:.3g} m: expected at least a fifth of the "
            f"wing {W:g} m x {H:g} m; {hint}"
        )
    v = frames.valid
    for k in ("u", "v", "w"):
        a = np.abs(np.where(v, getattr(frames, k), 0.0))
        if a.size and a.max() > 0.5 * H:
            f, p = np.unravel_index(np.argmax(a), a.shape)
            raise DataFileError(
                f"{name}: {k}[frame {f}, point {p}] = {a[f, p]:.4g} m: expected a displacement below half the "
                f"wing height {0.5 * H:g} m (mm read as m? declare unit = 'mm')"
            )
    if frames.strain_kind != "none":
        for k in ("exx", "eyy", "exy"):
            a = np.abs(np.where(v, getattr(frames, k), 0.0))
            if a.size and a.max() > MAX_STRAIN:
                f, p = np.unravel_index(np.argmax(a), a.shape)
                raise DataFileError(
                    f"{name}: {k}[frame {f}, point {p}] = {a[f, p]:.4g}: expected a strain below {MAX_STRAIN} "
                    "(strains in percent? declare strain_unit = 'percent')"
                )
