"""An identification in the ecosystem's containers: pandas (the lift history) and xarray (the field).

pandas, xarray and a NetCDF engine (h5netcdf or netCDF4) are an optional extra,
``pip install 'wingopt[data]'``; without them the functions here raise one line naming it, and
``wingopt identify`` writes everything but ``field.nc`` (a warning says why).

The dataset (:func:`field_dataset`): dimensions ``t``, ``x``, ``y`` (units as attributes);
``pressure(t, x, y)`` the field over time, ``pressure_mean(x, y)`` and ``pressure_std(x, y)`` the
field behind the reported lift and its band (:mod:`wingopt.results.field`), ``lift(t)`` and
``lift_std(t)`` the lift history; the reported lift in the attributes ``lift_N``, ``lift_std_N``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wingopt.errors import InputError, MissingExtraError
from wingopt.results.field import field_history, grid, mean_field

__all__ = ["lift_dataframe", "field_dataset", "write_netcdf", "HINT", "netcdf_engine"]

HINT = "pip install 'wingopt[data]' (pandas, xarray, h5netcdf, h5py)"


def _xarray():
    """xarray, or :class:`MissingExtraError` with the one-line install hint."""
    try:
        import xarray  # optional: the data extra
    except ImportError:
        raise MissingExtraError(f"xarray is not installed: {HINT}") from None
    return xarray


def netcdf_engine() -> str:
    """The NetCDF engine xarray will write with: ``h5netcdf`` (with h5py), else ``netcdf4`` (or the hint)."""
    try:
        import h5netcdf  # noqa: F401 - optional: the data extra's engine
        import h5py  # noqa: F401 - h5netcdf's backend

        return "h5netcdf"
    except ImportError:
        pass
    try:
        import netCDF4  # noqa: F401 - the other engine

        return "netcdf4"
    except ImportError:
        raise MissingExtraError(f"no NetCDF engine (h5netcdf with h5py, or netCDF4) is installed: {HINT}") from None


def lift_dataframe(result):
    """The lift history with its band as a :class:`pandas.DataFrame`
    (:meth:`IdentificationResult.to_dataframe <wingopt.estimation.core.result.IdentificationResult.to_dataframe>`)."""
    return result.to_dataframe()


def field_dataset(run, shape: tuple[int, int] = (57, 29), stride: int = 1, attrs: dict | None = None):
    """The run's field as an :class:`xarray.Dataset` (module docstring) on a ``shape = (nx, ny)`` grid.

    Parameters
    ----------
    run : IdentifyRun
    shape : (int, int)
        Grid points in x and y, edges included.
    stride : int
        Every ``stride``-th sample in ``pressure(t, x, y)``, ``lift(t)``, ``lift_std(t)`` (the mean
        field and its band use all).
    attrs : dict, optional
        More global attributes (provenance); values that are not numbers or strings become text.
    """
    xr = _xarray()
    if not isinstance(stride, int) or stride < 1:
        raise InputError(f"stride = {stride!r}: expected a positive integer")
    result = run.result
    X, Y = grid(run.problem, shape)
    mf = mean_field(result, run.model)
    idx = np.arange(0, len(result.t), stride)
    t, P = field_history(result, run.model, X, Y, idx)
    std = result.lift_std if result.lift_std is not None else np.full(len(result.t), np.nan)
    lift, band = result.reported_lift
    glob = {
        "title": f"wingopt identify: {run.problem.name}, {run.method}",
        "lift_N": lift,
        "lift_std_N": np.nan if band is None else band,
        "field_lift_N": mf.field_lift_N,
        "field": mf.as_dict()["what"],
        "band": mf.as_dict()["band"],
        "Conventions": "CF-1.8",
    }
    for k, v in (attrs or {}).items():
        glob[k] = v if isinstance(v, (int, float, str, np.number)) else str(v)
    ds = xr.Dataset(
        {
            "pressure": (("t", "x", "y"), P.transpose(0, 2, 1), {"units": "Pa", "long_name": "estimated pressure"}),
            "pressure_mean": (("x", "y"), mf(X, Y).T, {"units": "Pa", "long_name": "field behind the reported lift"}),
            "pressure_std": (("x", "y"), mf.std(X, Y).T, {"units": "Pa", "long_name": "1-sigma of pressure_mean"}),
            "lift": ("t", np.asarray(result.lift, dtype=float)[idx], {"units": "N", "long_name": "lift history"}),
            "lift_std": ("t", np.asarray(std, dtype=float)[idx], {"units": "N", "long_name": "1-sigma of lift"}),
        },
        coords={
            "t": ("t", np.asarray(t, dtype=float), {"units": "s", "long_name": "time"}),
            "x": ("x", X[0], {"units": "m", "long_name": "chordwise position"}),
            "y": ("y", Y[:, 0], {"units": "m", "long_name": "spanwise position"}),
        },
        attrs=glob,
    )
    return ds


def write_netcdf(ds, path: str | Path) -> Path:
    """Write ``ds`` to ``path`` as NetCDF-4, compressed; the history ``pressure(t, x, y)`` in single
    precision (7 digits of a pressure; half the file), the rest in double."""
    engine = netcdf_engine()
    # byte shuffle before gzip: a quarter smaller on a pressure history (7.6 -> 5.8 MB on the stand-in)
    zlib = {"zlib": True, "complevel": 4} if engine == "netcdf4" else {"compression": "gzip", "compression_opts": 4}
    zlib["shuffle"] = True
    enc = {v: dict(zlib) for v in ds.data_vars}
    if "pressure" in enc:
        enc["pressure"]["dtype"] = "float32"
    ds.to_netcdf(path, engine=engine, encoding=enc)
    return Path(path)
