"""Every exception the package raises on purpose.

Each error subclasses a builtin, so callers that only know Python still catch it
(``except ValueError`` works for bad input), while the command line maps the two
families to exit codes: :class:`InputError` -> 2, :class:`SolverError` -> 3.
"""

from __future__ import annotations

__all__ = [
    "WingoptError",
    "InputError",
    "ProblemFileError",
    "DataFileError",
    "OutputError",
    "MissingExtraError",
    "SolverError",
    "RiccatiAccuracyError",
]


class WingoptError(Exception):
    """Base class of all errors raised on purpose by wingopt."""


class InputError(WingoptError, ValueError):
    """Bad input from the user: a value, a file, an option.

    The message is one line that names the field, the value and what was expected.
    """


class ProblemFileError(InputError):
    """A problem file (TOML) that cannot be read or fails validation."""


class DataFileError(InputError):
    """A measured-data file (CSV) that cannot be used as it is."""


class OutputError(InputError, OSError):
    """An output location that cannot be written."""


class MissingExtraError(InputError, ImportError):
    """An optional package is not installed (the message names the extra: ``pip install 'wingopt[data]'``)."""


class SolverError(WingoptError, RuntimeError):
    """A numerical solver that did not deliver a usable answer.

    Parameters
    ----------
    backend : str
        Which solver failed (``"clarabel"``, ``"osqp"``, ``"ipopt"``, ...).
    status : str
        The solver's own status, as it reported it.
    hint : str
        What the user can try.
    context : str, optional
        Which choice of solver failed (``"qp"``: the QP backend, ``"mhe"``: the MHE window
        solver), for a front end to name the setting that picks another one.
    """

    def __init__(self, backend: str, status: str, hint: str = "", context: str | None = None) -> None:
        self.backend = backend
        self.status = status
        self.hint = hint
        self.context = context
        msg = f"{backend} failed with status {status!r}"
        if hint:
            msg += f"; {hint}"
        super().__init__(msg)


class RiccatiAccuracyError(SolverError):
    """A Riccati solution whose residual stays above the tolerance after rescaling and refinement.

    Raised instead of returning a gain that is silently wrong (e.g. ``scipy.linalg.solve_continuous_are``
    on a lightly damped full-order plate with a small input weight).
    """
