"""Calibration of the plate-wing layout against the dissertation's Tables 5.4 and 5.5.

Figure 5.4 (the layout) and Table 5.2 (the materials) are not legible in the source, so the layout
is rebuilt from the text (spec §3) with a few free geometric quantities, and those are fitted so
that the first four undamped frequencies match Table 5.4 in the seed's mode order (1st bending,
1st torsion, 2nd bending, 2nd torsion) while the first decay rates stay close to Table 5.5. The
actuation per volt is then scaled, through the electrode spacing ``Lpz`` of eq. 4.26, so that the
seed's twist result (±4 kV on PZ8/PZ9 → tip corners at about ±1 cm) is reproduced statically.

``benchmarks/calibrate_plate.py`` runs the whole procedure and prints the values that
``problems/plate.toml`` holds; ``docs/plate.md`` explains every choice.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from wingopt.plate.model import PlateModel
from wingopt.problem.plate import BattenSpec, PatchSpec, PlateProblem

__all__ = [
    "TABLE_5_4",
    "TABLE_5_5",
    "SEED_ORDER",
    "LayoutParameters",
    "seed_layout",
    "apply_layout",
    "ModalSummary",
    "modal_summary",
    "calibrate",
    "calibrate_electrode_spacing",
]

log = logging.getLogger(__name__)

TABLE_5_4 = {
    (7, 31): (10.116, 40.902, 50.719, 121.488),
    (13, 61): (9.777, 40.329, 49.940, 119.560),
    (25, 121): (9.692, 40.099, 49.638, 118.709),
}
"""First four undamped frequencies (Hz) per mesh, Table 5.4."""

TABLE_5_5 = {
    (7, 31): (-0.54380 + 63.559j, -0.39818 + 256.999j, -0.51519 + 318.681j, -0.38619 + 763.332j),
    (13, 61): (-0.54393 + 61.432j, -0.39834 + 253.397j, -0.51520 + 313.786j, -0.38664 + 751.222j),
    (25, 121): (-0.54395 + 60.899j, -0.39841 + 251.949j, -0.51521 + 311.887j, -0.38690 + 745.874j),
}
"""First four damped eigenvalues (1/s) per mesh, Table 5.5."""

SEED_ORDER = (("bending", 1), ("torsion", 1), ("bending", 2), ("torsion", 2))
"""Mode kinds of Figures 5.8–5.11, in frequency order."""


@dataclass(frozen=True)
class LayoutParameters:
    """The reconstructed layout of Figure 5.4 (m); x is the chord, y the span, y = 0 the tip.

    Battens: two edge battens of width ``edge_batten_width`` along the full span, a tip batten
    ``[0, chord_batten_width]`` and two ribs starting at ``ribs`` (chordwise battens), these three
    between the edge battens. Patches: PZ1/PZ4/PZ7 cover the tip batten and the ribs between the
    edge battens; PZ2/PZ3, PZ5/PZ6 and PZ8/PZ9 are pairs on the two edge battens (x = 0 first)
    spanning ``[edge_patch_start, edge_patch_start + edge_patch_length]``, ``mid_patch`` and
    ``[root_patch_start, L]``.
    """

    batten_thickness: float = 2.0e-3
    edge_batten_width: float = 0.025
    chord_batten_width: float = 0.025
    ribs: tuple[float, float] = (0.2, 0.4)
    edge_patch_start: float = 0.1
    edge_patch_length: float = 0.1
    mid_patch: tuple[float, float] = (0.25, 0.375)
    root_patch_start: float = 0.45

    def replace(self, **changes) -> LayoutParameters:
        return dataclasses.replace(self, **changes)


def seed_layout(width: float, length: float, p: LayoutParameters) -> tuple[tuple, tuple]:
    """Battens and patches (name, rectangle) of the layout ``p`` on a ``width x length`` plate."""
    W, L, be, bc = width, length, p.edge_batten_width, p.chord_batten_width
    r1, r2 = p.ribs
    battens = (
        BattenSpec("leading edge", (0.0, be, 0.0, L)),
        BattenSpec("trailing edge", (W - be, W, 0.0, L)),
        BattenSpec("tip", (be, W - be, 0.0, bc)),
        BattenSpec("rib 1", (be, W - be, r1, r1 + bc)),
        BattenSpec("rib 2", (be, W - be, r2, r2 + bc)),
    )
    spans = [
        (p.edge_patch_start, p.edge_patch_start + p.edge_patch_length),
        tuple(p.mid_patch),
        (p.root_patch_start, L),
    ]
    chord = [(0.0, bc), (r1, r1 + bc), (r2, r2 + bc)]
    patches = []
    for k, ((c0, c1), (s0, s1)) in enumerate(zip(chord, spans)):
        patches.append(PatchSpec(f"PZ{3 * k + 1}", (be, W - be, c0, c1)))
        patches.append(PatchSpec(f"PZ{3 * k + 2}", (0.0, be, s0, s1)))
        patches.append(PatchSpec(f"PZ{3 * k + 3}", (W - be, W, s0, s1)))
    return battens, tuple(patches)


def apply_layout(problem: PlateProblem, p: LayoutParameters) -> PlateProblem:
    """``problem`` with the battens, patches and batten thickness of the layout ``p``."""
    battens, patches = seed_layout(problem.width, problem.length, p)
    batten = dataclasses.replace(problem.batten, thickness=p.batten_thickness)
    return problem.replace(batten=batten, battens=battens, patches=patches)


@dataclass(frozen=True)
class ModalSummary:
    """Frequencies (Hz), mode kinds and damped eigenvalues of a model, with Table 5.4/5.5 errors."""

    nodes: tuple[int, int]
    frequencies_hz: np.ndarray
    kinds: tuple[tuple[str, int], ...]
    eigenvalues: np.ndarray
    build_seconds: float

    @property
    def in_seed_order(self) -> bool:
        return tuple(self.kinds[:4]) == SEED_ORDER

    @property
    def frequency_errors(self) -> np.ndarray:
        """Relative errors of the first four frequencies against Table 5.4 (this mesh)."""
        return self.frequencies_hz[:4] / np.asarray(TABLE_5_4[self.nodes]) - 1.0

    @property
    def decay_errors(self) -> np.ndarray:
        """Relative errors of the first four decay rates (real parts) against Table 5.5."""
        ref = np.asarray(TABLE_5_5[self.nodes]).real
        return self.eigenvalues[:4].real / ref - 1.0

    def table(self) -> str:
        """A plain-text table of this summary against the dissertation."""
        lines = [f"mesh {self.nodes[0]}x{self.nodes[1]} (build {self.build_seconds:.2f} s)"]
        head = f"{'mode':<12} {'f (Hz)':>9} {'Table 5.4':>10} {'err':>7}"
        lines.append(head + f"   {'Re s':>8} {'Table 5.5':>10} {'err':>7}")
        f_ref = TABLE_5_4.get(self.nodes)
        s_ref = TABLE_5_5.get(self.nodes)
        for k in range(min(4, self.frequencies_hz.size)):
            kind = f"{self.kinds[k][0]} {self.kinds[k][1]}"
            f, s = self.frequencies_hz[k], self.eigenvalues[k].real
            row = f"{kind:<12} {f:>9.3f}"
            row += f" {f_ref[k]:>10.3f} {100 * (f / f_ref[k] - 1):>6.1f}%" if f_ref else ""
            row += f"   {s:>8.4f}"
            row += f" {s_ref[k].real:>10.5f} {100 * (s / s_ref[k].real - 1):>6.1f}%" if s_ref else ""
            lines.append(row)
        for k in range(4, self.frequencies_hz.size):
            lines.append(f"{self.kinds[k][0] + ' ' + str(self.kinds[k][1]):<12} {self.frequencies_hz[k]:>9.3f}")
        return "\n".join(lines)


def modal_summary(problem: PlateProblem, nodes: tuple[int, int], count: int = 5) -> ModalSummary:
    """Build the model on ``nodes`` and summarise its first ``count`` modes."""
    model = PlateModel.from_problem(problem, nodes)
    freqs, shapes = model.modes(count)
    kinds = tuple(model.classify_mode(shapes[:, k]) for k in range(count))
    eigs = model.eigenvalues(min(count, 4))
    return ModalSummary(tuple(nodes), freqs, kinds, eigs, model.build_seconds)


def _modes(problem: PlateProblem, nodes: tuple[int, int], count: int) -> tuple[np.ndarray, tuple]:
    model = PlateModel.from_problem(problem, nodes)
    freqs, shapes = model.modes(count)
    return freqs, tuple(model.classify_mode(shapes[:, k]) for k in range(count))


def _residuals(summary: ModalSummary, fine: tuple, decay_weight: float, separation: float) -> np.ndarray:
    f_ref = np.asarray(TABLE_5_4[summary.nodes])
    r = [np.log(summary.frequencies_hz[:4] / f_ref)]
    r.append(decay_weight * np.log(summary.eigenvalues[:4].real / np.asarray(TABLE_5_5[summary.nodes]).real))
    # Keep the next mode clear of the 2nd torsion mode on the finest mesh: with narrow edge battens
    # it is a local mode of the skin panels, whose frequency drops much faster under refinement than
    # the global modes do, and it would take the 4th place on 25x121.
    freqs, kinds = fine
    r.append([3.0 * max(0.0, np.log(separation * freqs[3] / freqs[4]))])
    r.append([0.0 if summary.in_seed_order and tuple(kinds[:4]) == SEED_ORDER else 1.0])
    return np.concatenate(r)


def calibrate(
    problem: PlateProblem,
    start: LayoutParameters,
    free: dict[str, tuple[float, float]],
    nodes: tuple[int, int] = (13, 61),
    fine_nodes: tuple[int, int] = (25, 121),
    decay_weight: float = 0.3,
    separation: float = 1.1,
    max_evaluations: int = 40,
) -> tuple[LayoutParameters, ModalSummary]:
    """Fit the ``free`` layout parameters (name -> bounds) to Tables 5.4/5.5 on ``nodes``.

    Least squares on the log frequency errors of the first four modes, plus ``decay_weight`` times
    the log errors of their decay rates, plus penalties that keep the seed's mode order (on
    ``nodes`` and ``fine_nodes``) and the fifth mode at least ``separation`` times above the fourth
    on ``fine_nodes``.
    """
    names = list(free)
    lo = np.array([free[k][0] for k in names])
    hi = np.array([free[k][1] for k in names])
    x0 = np.clip([getattr(start, k) for k in names], lo, hi)

    def layout(x: Sequence[float]) -> LayoutParameters:
        return start.replace(**dict(zip(names, (float(v) for v in x))))

    def fun(x):
        trial = apply_layout(problem, layout(x))
        summary = modal_summary(trial, nodes)
        fine = _modes(trial, fine_nodes, 5)
        r = _residuals(summary, fine, decay_weight, separation)
        log.info(
            "%s -> f %s, Re s %s, fine f %s, |r| %.4f",
            np.round(x, 5),
            np.round(summary.frequencies_hz, 2),
            np.round(summary.eigenvalues.real, 3),
            np.round(fine[0], 2),
            float(np.linalg.norm(r)),
        )
        return r

    sol = least_squares(fun, x0, bounds=(lo, hi), x_scale=hi - lo, diff_step=1e-3, max_nfev=max_evaluations)
    best = layout(sol.x)
    return best, modal_summary(apply_layout(problem, best), nodes)


def calibrate_electrode_spacing(
    problem: PlateProblem,
    nodes: tuple[int, int] = (13, 61),
    volts: float = 4000.0,
    tip: float = 0.01,
    pair: tuple[str, str] = ("PZ8", "PZ9"),
) -> float:
    """``Lpz`` such that ``+volts`` on ``pair[0]`` and ``-volts`` on ``pair[1]`` give tip corners ±``tip``.

    The seed's twist result (§5.4.2): about ±4 kV on the root pair PZ8/PZ9 holds the tip corners at
    about ±1 cm. The static deflection is proportional to ``1/Lpz``, so one solve fixes it.
    """
    reference = problem.piezo.electrode_spacing or 1.0e-3
    trial = problem.replace(piezo=dataclasses.replace(problem.piezo, electrode_spacing=reference))
    model = PlateModel.from_problem(trial, nodes)
    u = np.zeros(model.n_inputs)
    names = list(model.patch_names)
    u[names.index(pair[0])], u[names.index(pair[1])] = volts, -volts
    corners = model.tip_corners(model.static_deflection(u))
    return reference * float(np.mean(np.abs(corners))) / tip
