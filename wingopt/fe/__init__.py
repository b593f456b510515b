"""Finite-element core: cubic B-spline bases, tensor spaces, weak forms and assembly."""

from wingopt.fe.bspline import EdgeCondition, SplineBasis1D, gauss_legendre
from wingopt.fe.forms import (
    DX,
    DXX,
    DXY,
    DY,
    DYY,
    VALUE,
    BilinearForm,
    Derivative,
    LinearForm,
    assemble,
    assemble_mixed,
    assemble_vector,
    integrate,
    separable,
)
from wingopt.fe.projection import load_vector, project
from wingopt.fe.space import Cells, Rect, TensorSpace

__all__ = [
    "EdgeCondition",
    "SplineBasis1D",
    "gauss_legendre",
    "TensorSpace",
    "Cells",
    "Rect",
    "Derivative",
    "BilinearForm",
    "LinearForm",
    "separable",
    "assemble",
    "assemble_mixed",
    "assemble_vector",
    "integrate",
    "load_vector",
    "project",
    "VALUE",
    "DX",
    "DY",
    "DXX",
    "DYY",
    "DXY",
]
