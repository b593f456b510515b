"""Load model of the realistic estimator: a smooth shape with a gust-following amplitude.

``P(x, y, t) = (1 + g(t)) * sum_s c_s psi_s(x, y)``:

* **shape** ``c``: coefficients on the ``count`` smoothest load shapes ``psi_s`` (generalised
  eigenvectors of ``(Lam, Gram)``, ``Lam psi = mu psi``, L2-normalised, zero on the edges), with
  the Gaussian smoothness prior ``c_s ~ N(0, (kappa |P0| sqrt(A) (mu_1 / mu_s)^power)^2)``: a load
  as rough as the ``s``-th shape is expected ``(mu_s / mu_1)^power`` times smaller than the prior
  pressure ``P0`` (the problem's ``initial_load``; ``power = 1`` is the seed's ``f^T Lam f``
  regulariser with a fixed weight). This prior is fixed before any data are seen and enters
  the band. A pressure that acts up to the frame (an aerodynamic load peaks at the leading edge)
  needs shapes that are not zero there: ``edge_shapes`` more, the smoothest of the free-edge
  spline space (eigenvectors of ``(Lam_f, Gram_f)``: the constant, ``x``, ``y``, ``xy``, ...), with
  the prior std ``kappa |P0| sqrt(A) min(1, k^4 / mu)`` (``k^4 = (pi/W)^4 + (pi/L)^4``, the
  smoothest interior shape's roughness): a uniform pressure of ``P0`` is as likely as the first
  interior shape. The four sensors do not resolve these from the interior shapes, so the
  posterior keeps their spread: the lift band covers a load the sensors cannot tell apart;
* **amplitude** ``g(t)``: piecewise linear on knots ``knot_s`` apart (seconds), prior ``g ~ N(0,
  level^2)`` per knot plus a second-difference (acceleration) prior of ``accel`` (1/s^2, relative to
  the steady load): the lift may change within tens of ms while the shape stays. ``g`` is off for a
  constant load.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from wingopt.errors import InputError
from wingopt.estimation.core.load_space import LoadSpace, build_load_space
from wingopt.membrane import MembraneModel

__all__ = ["LoadShapes", "GustAmplitude"]


AERO_TERMS = ((0, 0), (1, 0), (0, 1))
"""The aerodynamic shapes (chordwise term, spanwise term): the flat plate's and the camber's loads
over a uniform span, and the flat plate's over a centred parabola: as many amplitudes as four
sensors resolve."""


def _canonical(mu: np.ndarray, vecs: np.ndarray) -> np.ndarray:
    """Eigenvectors with each degenerate eigenspace's basis fixed by the space, not by LAPACK.

    The free-edge space's shapes come in equal pairs (and four null shapes: constant, ``x``, ``y``,
    ``xy``); ``eigh`` returns any orthonormal basis of such a space, and which one changed with the
    BLAS thread count. The prior is the same on the whole space, so the posterior is not changed by
    the choice, but a Levenberg–Marquardt step (its diagonal damping) and a fit stopped early are:
    the gust record's frame-prior lift moved by 1e-3 relative and its band by 3 % between one and
    two threads. Within a space the basis is the eigenvectors of a fixed generic diagonal
    ``diag(1 + i / n)`` restricted to it (distinct eigenvalues, so unique up to sign)."""
    n, k = vecs.shape
    out = np.array(vecs, dtype=float)
    scale = max(float(np.abs(mu).max(initial=0.0)), 1e-300)
    start = 0
    while start < k:
        stop = start + 1
        while stop < k and abs(mu[stop] - mu[start]) <= 1e-7 * max(abs(mu[start]), abs(mu[stop])) + 1e-10 * scale:
            stop += 1
        if stop - start > 1:
            U = out[:, start:stop]
            d = 1.0 + np.arange(n) / n
            _, R = np.linalg.eigh(U.T @ (d[:, None] * U))
            out[:, start:stop] = U @ R
        start = stop
    return out


def _oriented(vecs: np.ndarray, integrals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvectors with a sign fixed by the shapes themselves, not by LAPACK, and their lifts: a
    positive lift, or, for a shape without lift (antisymmetric: its lift is rounding, about 1e-17),
    a positive first clearly non-zero entry (the sign of such a shape changed with the BLAS thread
    count)."""
    lift = vecs.T @ integrals
    scale = np.abs(vecs).max(axis=0)
    tiny = np.abs(lift) <= 1e-9 * max(float(np.abs(lift).max(initial=0.0)), 1e-300)
    first = np.argmax(np.abs(vecs) > 1e-3 * scale[None, :], axis=0)
    by_entry = np.sign(vecs[first, np.arange(vecs.shape[1])])
    sign = np.where(tiny, np.where(by_entry < 0, -1.0, 1.0), np.where(lift < 0, -1.0, 1.0))
    return vecs * sign, lift * sign


@dataclass(frozen=True, eq=False)
class LoadShapes:
    """The smoothest load shapes of a model's deflection basis and their prior.

    Attributes
    ----------
    shapes : ndarray ``(n_f, count)``
        Coefficients of each shape (``∫ psi_s^2 = 1``) in the load basis: the deflection basis, or
        with ``edge_shapes`` the free-edge spline basis of ``space``.
    mu : ndarray ``(count,)``
        Roughness ``∫ (psi_xx^2 + psi_yy^2)``.
    prior_std : ndarray ``(count,)``
        Prior standard deviation of each coefficient (Pa m).
    lift_row : ndarray ``(count,)``
        ``∫ psi_s``: lift = ``lift_row @ c``.
    forces : ndarray ``(n, count)``
        Load vector ``∫ phi_w psi_s`` of each shape in the deflection equation (``p = M f`` for a
        shape of the deflection basis).
    space : LoadSpace or None
        The load basis of ``shapes`` (``None``: the deflection basis).
    """

    shapes: np.ndarray
    mu: np.ndarray
    prior_std: np.ndarray
    lift_row: np.ndarray
    forces: np.ndarray
    space: LoadSpace | None = None

    @classmethod
    def build(
        cls,
        model: MembraneModel,
        count: int = 15,
        pressure: float = 200.0,
        kappa: float = 1.0,
        power: float = 1.0,
        edge_shapes: int = 0,
    ) -> LoadShapes:
        """``count`` smoothest shapes; ``pressure`` the prior pressure scale (Pa), ``kappa`` its factor,
        ``power`` the decay of the prior std with roughness, ``(mu_1/mu_s)^power``; ``edge_shapes``
        smoothest free-edge shapes more (a load that acts up to the frame)."""
        if not 1 <= count <= model.n:
            raise InputError(f"load shapes = {count}: expected 1..{model.n}")
        if not (np.isfinite(pressure) and pressure != 0 and kappa > 0):
            raise InputError(f"load prior: pressure {pressure!r} and kappa {kappa!r} must be non-zero and positive")
        mu, vecs = sla.eigh(model.regularizer.toarray(), model.gram.toarray(), subset_by_index=(0, count - 1))
        area = model.problem.width * model.problem.height
        std = kappa * abs(pressure) * np.sqrt(area) * (mu[0] / mu) ** power
        # Orientation: a positive first coefficient means a positive mean pressure.
        vecs, lift = _oriented(_canonical(mu, vecs), model.basis_integrals)
        forces = np.asarray(model.gram @ vecs)
        if not edge_shapes:
            return cls(vecs, mu, std, lift, forces)
        free = build_load_space(model, "free", edge_weight=0.0)
        if not 0 < edge_shapes <= free.n:
            raise InputError(f"edge shapes = {edge_shapes!r}: expected 0..{free.n}")
        muf, V = sla.eigh(free.regularizer.toarray(), free.gram.toarray(), subset_by_index=(0, edge_shapes - 1))
        muf = np.maximum(muf, 0.0)
        V, liftf = _oriented(_canonical(muf, V), free.basis_integrals)
        k4 = (np.pi / model.problem.width) ** 4 + (np.pi / model.problem.height) ** 4
        stdf = kappa * abs(pressure) * np.sqrt(area) * np.minimum(1.0, k4 / np.maximum(muf, 1e-300))
        return cls(
            np.hstack([model.space.transform @ vecs, V]),
            np.concatenate([mu, muf]),
            np.concatenate([std, stdf]),
            np.concatenate([lift, liftf]),
            np.hstack([forces, np.asarray(free.coupling @ V)]),
            free,
        )

    @classmethod
    def none(cls, model: MembraneModel) -> LoadShapes:
        """No load at all (a calibration record: free vibration)."""
        return cls(np.zeros((model.n, 0)), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((model.n, 0)))

    @property
    def count(self) -> int:
        return self.mu.size

    def coefficients(self, c: np.ndarray) -> np.ndarray:
        """Load coefficients (in the load basis, :attr:`space`) of shape coefficients ``c`` (``(..., count)``)."""
        return np.asarray(c) @ self.shapes.T

    @classmethod
    def aerodynamic(
        cls, model: MembraneModel, pressure: float = 200.0, leading_edge: str = "x0", kappa: float = 1.0
    ) -> LoadShapes:
        """Thin-airfoil pressure shapes that act up to the frame, with their leading edge at ``x = 0``
        (``"x0"``) or ``x = W`` (``"x1"``).

        Chordwise (``xi`` from the leading edge, ``theta`` its Glauert angle): the regularised
        flat-plate term ``sqrt((1 - xi + d)/(xi + d))`` (``d = 0.05``: the leading edge's singularity
        rounded off), the camber terms ``sin theta ~ sqrt(xi (1 - xi))`` and ``sin 2 theta``, and a
        uniform pressure; spanwise (``eta = y / L``): uniform, a centred parabola and a linear tilt,
        none of them zero on the frame. Their twelve products, L2-normalised, carry the prior std
        ``kappa |P0| sqrt(A)`` for the uniform-span flat-plate and camber terms and half of it for the
        rest: an aerodynamic load has its lift set by a few amplitudes, which four sensors resolve.
        """
        if leading_edge not in ("x0", "x1"):
            raise InputError(f"leading_edge = {leading_edge!r}: expected 'x0' (x = 0) or 'x1' (x = W)")
        free = build_load_space(model, "free", edge_weight=0.0)
        W, L = model.problem.width, model.problem.height
        d = 0.05

        def chord(j):
            def f(x, y):
                xi = x / W if leading_edge == "x0" else 1.0 - x / W
                s1 = np.sqrt(np.clip(xi * (1.0 - xi), 0.0, None))
                return (np.sqrt((1 - xi + d) / (xi + d)), s1, s1 * (1 - 2 * xi), np.ones_like(xi))[j]

            return f

        def span(k):
            def g(x, y):
                eta = y / L
                return (np.ones_like(eta), 4 * eta * (1 - eta) - 2.0 / 3.0, 2 * eta - 1)[k]

            return g

        vecs, std = [], []
        for j, k in AERO_TERMS:
            fj, gk = chord(j), span(k)
            v = free.project(lambda x, y, fj=fj, gk=gk: fj(x, y) * gk(x, y))
            vecs.append(v / free.l2_norm(v))
            std.append(kappa * abs(pressure) * np.sqrt(W * L))
        V = np.column_stack(vecs)
        lift = V.T @ free.basis_integrals
        return cls(V, np.zeros(V.shape[1]), np.array(std), lift, np.asarray(free.coupling @ V), free)

    def modal_forces(self, modes: np.ndarray) -> np.ndarray:
        """Modal force ``Phi^T p`` of each shape ``(count, m)`` for mode shapes ``Phi`` ``(n, m)``."""
        return (modes.T @ self.forces).T


@dataclass(frozen=True)
class GustAmplitude:
    """Piecewise-linear relative amplitude ``g(t)`` on knots ``knot_s`` apart.

    ``accel`` (1/s^2): prior std of the second derivative of ``g`` (a 1-cos gust of relative
    size ``a`` and duration ``T`` has ``a/2 (2 pi / T)^2``: 300 for +60 % over 0.2 s); ``level``:
    prior std of ``g`` itself (it only removes the trade-off between ``g`` and the shape's size).
    """

    knot_s: float = 0.01
    accel: float = 300.0
    level: float = 1.0

    def __post_init__(self) -> None:
        for name in ("knot_s", "accel", "level"):
            val = getattr(self, name)
            if not (np.isfinite(val) and val > 0):
                raise InputError(f"gust {name} = {val!r}: expected a positive number")

    def knots(self, t: np.ndarray) -> np.ndarray:
        """Knot times covering ``t`` (first and last sample included)."""
        n = max(int(np.ceil((t[-1] - t[0]) / self.knot_s - 1e-9)), 1)
        return t[0] + np.arange(n + 1) * ((t[-1] - t[0]) / n)

    def basis(self, t: np.ndarray) -> np.ndarray:
        """Hat functions ``(len(t), n_knots)``: ``g(t_k) = H[k] @ g_knots``."""
        kn = self.knots(t)
        H = np.zeros((t.size, kn.size))
        j = np.clip(np.searchsorted(kn, t, side="right") - 1, 0, kn.size - 2)
        w = (t - kn[j]) / (kn[j + 1] - kn[j])
        H[np.arange(t.size), j] = 1 - w
        H[np.arange(t.size), j + 1] += w
        return H

    def prior_rows(self, t: np.ndarray) -> np.ndarray:
        """Rows ``R`` of the prior ``|R g|^2`` (level rows and second-difference rows)."""
        kn = self.knots(t)
        n, h = kn.size, kn[1] - kn[0]
        rows = [np.eye(n) / self.level]
        if n >= 3:
            D = np.zeros((n - 2, n))
            idx = np.arange(n - 2)
            D[idx, idx], D[idx, idx + 1], D[idx, idx + 2] = 1.0, -2.0, 1.0
            # (g_{j+1} - 2 g_j + g_{j-1}) / h^2 ~ g'', prior std accel
            rows.append(D / (self.accel * h * h))
        return np.vstack(rows)
