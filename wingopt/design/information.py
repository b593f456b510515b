"""Fisher information of candidate stretch sensors, linearised along an expected response (spec §9).

A stretch sensor reads ``s_i = z^T C_i z``. With the lowest ``m`` M-orthonormal modes ``Phi`` the
estimator's unknowns are the initial modal state ``(q0, q0')`` and the modal load ``u = Phi^T M f``
(the data see the load only through ``u``), and the modal displacement is *linear* in them::

    q_k = a_k * q0 + a'_k * q0' + b_k * u        (element-wise per mode, exact ZOH)

so the sensitivity of one output sample is ``ds_{k,i}/dtheta = 2 (C^_i q_k) * [a_k, a'_k, b_k]``
with ``C^_i = Phi^T C_i Phi`` and ``q_k`` the *expected* response (the transient from the initial
bubble under a nominal load: at ``q = 0`` the sensitivity vanishes). The information of sensor ``i``
over a record is ``F_i = sum_k J_ik^T J_ik / sigma_i^2`` with the protocol's noise
``sigma_i = p max_k |s_i(q_k)|``. The initial state is a nuisance: only its lowest ``state_modes``
modes are kept as unknowns (higher modes decay within a few samples and carry no load
information), so ``theta`` has ``d = 2 state_modes + m`` entries.

Candidates on the lattice of ``sub`` x ``sub`` cells per element get ``C^_i`` from 2-D prefix sums of
per-cell matrices (exact: the splines are polynomial in each cell), so a thousand candidates cost
one quadrature of the modal gradients; other rectangles are integrated cell by cell.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.declaration import declaration_of
from wingopt.fe import Cells
from wingopt.membrane import MembraneModel, bubble

__all__ = ["InformationSettings", "ModalSensitivity", "SegmentInformation"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class InformationSettings:
    """How the information is linearised.

    Parameters
    ----------
    modes : int
        Load modes ``m`` (the estimator's default is 40).
    state_modes : int
        Modes of the initial state kept as nuisance unknowns.
    t_end : float
        Record length (s).
    window_s : float
        Length of the first segment (s), the estimator's first window (its lambda rule runs there).
    noise_fraction : float
        Noise as a fraction of each sensor's peak output (0.01 = 1 %).
    sub : int
        Lattice cells per element and direction (candidate edges lie on this lattice).
    rest_stride : int
        After the first window, every ``rest_stride``-th sample is used with weight ``rest_stride``
        (the response is then slowly varying); 1 (default) uses every sample.
    """

    modes: int = 40
    state_modes: int = 12
    t_end: float = 1.0
    window_s: float = 0.2
    noise_fraction: float = 0.01
    sub: int = 2
    rest_stride: int = 1

    def __post_init__(self):
        def bad(name, expect):
            raise InputError(f"{name} = {getattr(self, name)!r}: expected {expect}")

        if not (isinstance(self.modes, int) and self.modes >= 2):
            bad("modes", "an integer >= 2")
        if not (isinstance(self.state_modes, int) and 0 <= self.state_modes <= self.modes):
            bad("state_modes", f"an integer in 0..modes ({self.modes})")
        if not (np.isfinite(self.t_end) and self.t_end > 0):
            bad("t_end", "a positive duration (s)")
        if not (np.isfinite(self.window_s) and 0 < self.window_s <= self.t_end):
            bad("window_s", "a duration in (0, t_end]")
        if not (np.isfinite(self.noise_fraction) and self.noise_fraction > 0):
            bad("noise_fraction", "a positive fraction of the peak output (0.01 = 1 %)")
        if not (isinstance(self.sub, int) and self.sub >= 1):
            bad("sub", "an integer >= 1")
        if not (isinstance(self.rest_stride, int) and self.rest_stride >= 1):
            bad("rest_stride", "an integer >= 1")


@dataclass(frozen=True, eq=False)
class SegmentInformation:
    """Per-candidate information of one nominal response, split in the first window and the rest.

    ``window`` and ``rest`` are ``(N, d, d)``, ``peak`` the peak
    output ``max |s_i|`` per candidate and ``samples`` the sample counts of the two segments.
    """

    window: np.ndarray
    rest: np.ndarray
    peak: np.ndarray
    samples: tuple[int, int]

    @property
    def total(self) -> np.ndarray:
        return self.window + self.rest

    def layout(self, index, segment: str = "total") -> np.ndarray:
        """Summed information ``(d, d)`` of the candidates ``index`` (float64)."""
        idx = np.asarray(index, dtype=int)
        if segment == "window":
            return self.window[idx].sum(axis=0)
        return self.window[idx].sum(axis=0) + self.rest[idx].sum(axis=0)


@dataclass(eq=False)
class ModalSensitivity:
    """Modal sequences of a membrane model and the information of candidate rectangles.

    Build with :meth:`from_model`; :meth:`modal_matrices` gives ``C^_i`` of rectangles,
    :meth:`information` the per-candidate information along a nominal response.
    """

    model: MembraneModel
    settings: InformationSettings
    omega: np.ndarray
    shapes: np.ndarray  # (n, m), M-orthonormal in rho h M
    input_matrix: np.ndarray  # (m, n): u = input_matrix @ f
    seq: np.ndarray  # (T+1, m, 3): a, a', b per sample and mode
    dt: float
    _cache: dict = field(default_factory=dict)

    @classmethod
    def from_model(cls, model: MembraneModel, settings: InformationSettings | None = None) -> ModalSensitivity:
        s = settings or InformationSettings()
        if s.modes > model.n:
            raise InputError(f"modes = {s.modes}: expected at most {model.n} for this mesh")
        modal = model.modal(s.modes)
        dt = declaration_of(model.problem).dt
        disc = modal.discretize(dt)
        steps = int(round(s.t_end / dt))
        if steps < 2:
            raise InputError(f"t_end = {s.t_end!r}: shorter than two samples (dt = {dt})")
        F, g = disc.F, disc.g
        m = modal.count
        seq = np.zeros((steps + 1, m, 3))
        # Columns: response to q0 = 1, to q0' = 1 and to a unit constant modal drive, from rest.
        st = np.zeros((3, 2, m))
        st[0, 0] = 1.0
        st[1, 1] = 1.0
        seq[0, :, 0] = 1.0
        drive = np.array([0.0, 0.0, 1.0])[:, None]
        for k in range(steps):
            q = F[:, 0, 0] * st[:, 0] + F[:, 0, 1] * st[:, 1] + g[:, 0] * drive
            qd = F[:, 1, 0] * st[:, 0] + F[:, 1, 1] * st[:, 1] + g[:, 1] * drive
            st[:, 0], st[:, 1] = q, qd
            seq[k + 1] = q.T
        seq[np.abs(seq) < 1e-250] = 0.0
        return cls(model, s, modal.omega, modal.shapes, modal.input_matrix, seq, dt)

    # -- sizes --------------------------------------------------------------------------
    @property
    def m(self) -> int:
        return self.omega.size

    @property
    def dim(self) -> int:
        """``d = 2 state_modes + m``: unknowns ``[q0 (low), q0' (low), u]``."""
        return 2 * self.settings.state_modes + self.m

    @property
    def steps(self) -> int:
        return self.seq.shape[0] - 1

    @property
    def window_samples(self) -> int:
        return max(2, min(self.steps + 1, int(round(self.settings.window_s / self.dt))))

    # -- responses ------------------------------------------------------------------------
    def modal_load(self, f: np.ndarray) -> np.ndarray:
        """``u = Phi^T M f`` of load coefficients in the deflection basis."""
        return self.input_matrix @ np.asarray(f, dtype=float)

    def initial_state(self, peak: float | None = None) -> np.ndarray:
        """Modal displacement of the protocol's initial bubble (``peak`` m; default the problem's)."""
        prob = self.model.problem
        peak = declaration_of(prob).initial_deflection if peak is None else peak
        if peak == 0:
            peak = 0.01  # the protocol's bubble: the design needs an expected transient
        z0 = self.model.project(bubble(prob.width, prob.height, peak))
        return self.shapes.T @ (self.model.mass @ z0)

    def response(self, u: np.ndarray, q0: np.ndarray) -> np.ndarray:
        """Modal displacement ``(T+1, m)`` from ``(q0, 0)`` under the constant modal load ``u``."""
        return self.seq[:, :, 0] * q0[None, :] + self.seq[:, :, 2] * u[None, :]

    # -- sensor matrices --------------------------------------------------------------------
    @cached_property
    def _lattice(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Lattice lines ``xs``, ``ys`` and prefix sums ``(nx+1, ny+1, m, m)`` of the cell matrices."""
        sp_ = self.model.space
        ex_n, ey_n = sp_.n_elements
        sub = self.settings.sub
        xs = np.linspace(0.0, sp_.width, ex_n * sub + 1)
        ys = np.linspace(0.0, sp_.height, ey_n * sub + 1)
        ix, iy = np.meshgrid(np.arange(xs.size - 1), np.arange(ys.size - 1), indexing="ij")
        ix, iy = ix.ravel(), iy.ravel()
        cells = Cells(ix // sub, iy // sub, xs[ix], xs[ix + 1], ys[iy], ys[iy + 1])
        mats = self._cell_matrices(cells).reshape(xs.size - 1, ys.size - 1, self.m, self.m)
        pre = np.zeros((xs.size, ys.size, self.m, self.m))
        pre[1:, 1:] = mats.cumsum(axis=0).cumsum(axis=1)
        return xs, ys, pre

    def _cell_matrices(self, cells: Cells) -> np.ndarray:
        """``∫_cell (Phi_x^T Phi_x + Phi_y^T Phi_y)`` per cell, ``(ncell, m, m)`` (4x4 Gauss: exact)."""
        x, y, w = cells.quadrature(4)
        sp_ = self.model.space
        gx = (sp_.basis_matrix(x.ravel(), y.ravel(), dx=1) @ self.shapes).reshape(*x.shape, self.m)
        gy = (sp_.basis_matrix(x.ravel(), y.ravel(), dy=1) @ self.shapes).reshape(*x.shape, self.m)
        return np.einsum("cq,cqi,cqj->cij", w, gx, gx) + np.einsum("cq,cqi,cqj->cij", w, gy, gy)

    def lattice_index(self, rects: np.ndarray, tol: float = 1e-9) -> np.ndarray | None:
        """Lattice indices ``(N, 4)`` of rectangles whose edges all lie on the lattice, else ``None``."""
        xs, ys, _ = self._lattice
        rects = np.atleast_2d(np.asarray(rects, dtype=float))
        hx, hy = xs[1] - xs[0], ys[1] - ys[0]
        ix = np.rint(rects[:, :2] / hx)
        iy = np.rint(rects[:, 2:] / hy)
        if np.max(np.abs(ix * hx - rects[:, :2]), initial=0) > tol * hx:
            return None
        if np.max(np.abs(iy * hy - rects[:, 2:]), initial=0) > tol * hy:
            return None
        return np.column_stack([ix, iy]).astype(int)

    def modal_matrices(self, rects, gains=None) -> np.ndarray:
        """``C^_i = alpha_i/(2 A_i) Phi^T (∫_rect phi_x phi_x^T + phi_y phi_y^T) Phi``, ``(N, m, m)``."""
        rects = np.atleast_2d(np.asarray(rects, dtype=float))
        gains = np.ones(len(rects)) if gains is None else np.broadcast_to(np.asarray(gains, float), (len(rects),))
        for r in rects:
            self.model.space.check_rect(tuple(r), name="candidate rect")
        area = (rects[:, 1] - rects[:, 0]) * (rects[:, 3] - rects[:, 2])
        idx = self.lattice_index(rects)
        if idx is not None:
            _, _, pre = self._lattice
            i0, i1, j0, j1 = idx.T
            raw = pre[i1, j1] - pre[i0, j1] - pre[i1, j0] + pre[i0, j0]
        else:
            raw = np.stack([self._cell_matrices(self.model.space.cells(tuple(r))).sum(axis=0) for r in rects])
        raw = 0.5 * (raw + raw.transpose(0, 2, 1))
        return raw * (gains / (2.0 * area))[:, None, None]

    # -- information ----------------------------------------------------------------------
    def _cq(self, chat: np.ndarray, q: np.ndarray) -> np.ndarray:
        """``C^_i q_k`` ``(N, T+1, m)``, shared by the outputs and the Jacobian (computed once: the
        three-operand ``einsum`` of the outputs ran as a plain loop, much of the design's time).
        The summation order is kept as it was: the D relaxation's solver is sensitive to the last bits."""
        return np.einsum("cij,tj->cti", chat, q)

    def jacobian(self, chat: np.ndarray, q: np.ndarray, cq: np.ndarray | None = None) -> np.ndarray:
        """``ds_{k,i}/dtheta`` ``(N, T+1, d)`` of sensors ``chat`` ``(N, m, m)`` along ``q`` ``(T+1, m)``."""
        ms = self.settings.state_modes
        cq = self._cq(chat, q) if cq is None else cq
        basis = np.concatenate([self.seq[:, :ms, 0], self.seq[:, :ms, 1], self.seq[:, :, 2]], axis=1)
        sel = np.concatenate([np.arange(ms), np.arange(ms), np.arange(self.m)])
        return 2.0 * cq[:, :, sel] * basis[None]

    def outputs(self, chat: np.ndarray, q: np.ndarray, cq: np.ndarray | None = None) -> np.ndarray:
        """Clean outputs ``(T+1, N)`` of sensors ``chat`` along ``q``."""
        cq = self._cq(chat, q) if cq is None else cq
        return np.einsum("cti,ti->tc", cq, q)

    def information(
        self, chat: np.ndarray, u: np.ndarray, q0: np.ndarray, chunk: int = 64, noise_fraction: float | None = None
    ) -> SegmentInformation:
        """Information of every candidate along the response from ``q0`` under modal load ``u``.

        The noise of each candidate is ``noise_fraction * max_k |s_i(q_k)|`` (default: the settings'),
        the protocol's rule; the first ``window_samples`` samples form the window segment.
        """
        p = self.settings.noise_fraction if noise_fraction is None else noise_fraction
        q = self.response(u, q0)
        nw = self.window_samples
        N, d = chat.shape[0], self.dim
        win = np.empty((N, d, d))
        rest = np.empty((N, d, d))
        peak = np.empty(N)
        for a in range(0, N, chunk):
            c = chat[a : a + chunk]
            cq = self._cq(c, q)
            s = self.outputs(c, q, cq)
            pk = np.max(np.abs(s), axis=0)
            if np.any(pk <= 0):
                raise InputError("candidate sensor: reads zero along the nominal response (no information)")
            peak[a : a + chunk] = pk
            J = self.jacobian(c, q, cq) / (p * pk)[:, None, None]
            Jt = J.transpose(0, 2, 1)
            win[a : a + chunk] = Jt[:, :, :nw] @ J[:, :nw]
            st = self.settings.rest_stride
            rest[a : a + chunk] = st * (Jt[:, :, nw::st] @ J[:, nw::st])
        return SegmentInformation(win, rest, peak, (nw, self.steps + 1 - nw))
