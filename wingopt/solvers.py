"""Compatibility: the status vocabulary moved to :mod:`wingopt.optim.status` (import it from there)."""

from wingopt.optim.registry import BACKENDS
from wingopt.optim.status import SolveStatus, require_success, status_from

__all__ = ["SolveStatus", "status_from", "require_success", "BACKENDS"]
