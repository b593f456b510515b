"""Moved to :mod:`wingopt.estimation.mhe.cold_start`; this name stays until its last importer moves.

``wingopt/estimation/streaming/estimator.py`` still imports :func:`smooth_load_shapes` from here.
"""

from wingopt.estimation.mhe.cold_start import smooth_load_shapes

__all__ = ["smooth_load_shapes"]
