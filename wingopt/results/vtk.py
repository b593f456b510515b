"""Export spline fields to VTK (``.vtu``) for ParaView, through the optional ``meshio`` package."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from wingopt.fe import TensorSpace

__all__ = ["export_vtk"]


def export_vtk(
    path: str | Path,
    space: TensorSpace,
    fields: Mapping[str, np.ndarray],
    grid: tuple[int, int] = (61, 31),
    warp: str | None = None,
) -> Path:
    """Write fields (coefficient vectors on ``space``) sampled on a uniform quad grid.

    Parameters
    ----------
    path : path-like
        Output file; the extension chooses the format (``.vtu`` recommended).
    space : TensorSpace
        The space the coefficients live in.
    fields : mapping name -> coefficients ``(n,)`` or callable ``(x, y) -> values``
        Written as point data (callables for fields in another basis, e.g. an estimated load).
    grid : (nx, ny)
        Sampling points per direction, edges included.
    warp : str, optional
        Name of a field to use as the z coordinate (e.g. the deflection), so the surface shows
        its shape; otherwise the grid is flat.
    """
    try:
        import meshio
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("VTK export needs meshio: pip install 'wingopt[interop]'") from exc
    nx, ny = grid
    xs = np.linspace(0.0, space.width, nx)
    ys = np.linspace(0.0, space.height, ny)
    X, Y = np.meshgrid(xs, ys, indexing="ij")  # point index i * ny + j
    values = {
        name: np.asarray(f(X.ravel(), Y.ravel()) if callable(f) else space.evaluate(f, X.ravel(), Y.ravel()), float)
        for name, f in fields.items()
    }
    Z = values[warp] if warp else np.zeros(X.size)
    points = np.column_stack([X.ravel(), Y.ravel(), Z])
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="ij")
    p0 = (i * ny + j).ravel()
    quads = np.column_stack([p0, p0 + ny, p0 + ny + 1, p0 + 1])
    mesh = meshio.Mesh(points, [("quad", quads)], point_data=values)
    path = Path(path)
    mesh.write(path)
    return path
