"""Piecewise-constant material properties of the plate wing, cell by cell.

The domain is cut into integration cells at every element edge and at every batten and patch edge
(:meth:`~wingopt.fe.TensorSpace.cells`), so each cell lies in one region and every integral below is
exact for any rectangle, on or off the mesh lines. Each cell gets:

* the substrate laminate: the skin, or the batten that covers it (later battens in the file win
  where battens overlap), and its thickness ``h``;
* if a patch covers it, the piezocomposite pair on both faces of that substrate (eqs. 4.22–4.25):
  areal mass ``2 rho_pz h_pz``, rigidity ``2 c3 Q_pz`` and Kelvin–Voigt ``2 c3 eta_pz`` with
  ``c3 = ∫_{h/2}^{h/2+h_pz} z^2 dz``, and the actuation moments per volt of eq. 4.26;
* the viscous (air) damping ``gamma`` of the outer material (the patch where there is one).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wingopt.fe import Cells, TensorSpace
from wingopt.materials import moment_integrals, symmetric_pair_rigidity
from wingopt.problem.plate import PlateProblem

__all__ = ["CellProperties", "cell_properties", "actuation_moments"]


@dataclass(frozen=True, eq=False)
class CellProperties:
    """Material data of every integration cell (arrays of leading length ``len(cells)``).

    Attributes
    ----------
    cells : Cells
    region : int array
        0 for the skin, ``k + 1`` for batten ``k`` (file order).
    patch : int array
        Index of the patch on the cell (file order), -1 where there is none.
    thickness : array
        Substrate thickness ``h`` (skin or batten, without patches), m.
    areal_density : array
        ``rho h + 2 rho_pz h_pz`` (eq. 4.22), kg/m^2.
    rigidity, viscosity : arrays ``(ncell, 3, 3)``
        ``D`` and the Kelvin–Voigt ``eta`` of the cell's laminate including any patch pair.
    viscous : array
        ``gamma``, Pa s/m.
    moment_x, moment_y : arrays
        External moments per volt ``Mx_ext, My_ext`` of the cell's patch (0 without one), N m/m/V.
    """

    cells: Cells
    region: np.ndarray
    patch: np.ndarray
    thickness: np.ndarray
    areal_density: np.ndarray
    rigidity: np.ndarray
    viscosity: np.ndarray
    viscous: np.ndarray
    moment_x: np.ndarray
    moment_y: np.ndarray


def _inside(rect, x, y) -> np.ndarray:
    x0, x1, y0, y1 = rect
    return (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)


def actuation_moments(problem: PlateProblem, substrate: np.ndarray, patch_length: float) -> tuple:
    """External moments per volt (eq. 4.26): ``Mx = Y1 d33 c2/(Lpz (1-nu12))``, ``My = Y2 d33 c2/(Lpz (1-nu21))``.

    ``c2 = ∫_{h/2}^{h/2+h_pz} z dz`` over the patch on a substrate of thickness ``h``; ``Lpz`` is the
    length over which the voltage acts: the piezo's ``electrode_spacing`` if the file gives one, else
    ``patch_length`` (the patch's extent along x, the dissertation's literal reading).
    """
    pz = problem.piezo
    m = pz.material
    c2, _ = moment_integrals(substrate, pz.thickness)
    if pz.electrode_spacing is not None:
        patch_length = pz.electrode_spacing
    mx = m.e1 * pz.d33 * c2 / (patch_length * (1.0 - m.nu12))
    my = m.e2 * pz.d33 * c2 / (patch_length * (1.0 - m.nu21))
    return mx, my


def cell_properties(problem: PlateProblem, space: TensorSpace) -> CellProperties:
    """Cells of ``space`` split at every region edge, with their material data."""
    rects = [b.rect for b in problem.battens] + [p.rect for p in problem.patches]
    breaks_x = sorted({r[i] for r in rects for i in (0, 1)})
    breaks_y = sorted({r[i] for r in rects for i in (2, 3)})
    cells = space.cells(None, breaks_x, breaks_y)
    xm, ym = 0.5 * (cells.x0 + cells.x1), 0.5 * (cells.y0 + cells.y1)
    ncell = len(cells)

    region = np.zeros(ncell, dtype=int)
    for k, b in enumerate(problem.battens):
        region[_inside(b.rect, xm, ym)] = k + 1
    laminates = [problem.skin] + [problem.batten.with_angles(b.angles) for b in problem.battens]
    thickness = np.array([lam.thickness for lam in laminates])[region]
    rho_h = np.array([lam.areal_density for lam in laminates])[region]
    D = np.stack([lam.rigidity() for lam in laminates])[region]
    eta = np.stack([lam.viscosity() for lam in laminates])[region]
    gamma = np.array([lam.material.viscous for lam in laminates])[region]

    patch = np.full(ncell, -1, dtype=int)
    for i, p in enumerate(problem.patches):
        patch[_inside(p.rect, xm, ym)] = i
    on = patch >= 0
    pz = problem.piezo
    mx = np.zeros(ncell)
    my = np.zeros(ncell)
    if np.any(on):
        h = thickness[on]
        rho_h[on] += 2.0 * pz.material.density * pz.thickness
        D[on] += symmetric_pair_rigidity(pz.material.stiffness(), h, pz.thickness)
        eta[on] += symmetric_pair_rigidity(pz.material.viscosity(), h, pz.thickness)
        gamma[on] = pz.material.viscous
        lengths = np.array([p.rect[1] - p.rect[0] for p in problem.patches])[patch[on]]
        mx[on], my[on] = actuation_moments(problem, h, lengths)
    return CellProperties(cells, region, patch, thickness, rho_h, D, eta, gamma, mx, my)
