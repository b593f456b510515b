"""Studies as sweeps of independent runs on one engine (dask.distributed or serial)."""
