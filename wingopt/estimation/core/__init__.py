"""What every estimator shares, whatever its record or model: today the one nonlinear least-squares
solver (:mod:`.least_squares`, Levenberg–Marquardt) that the moving-horizon windows and the record
fits (transient, steady, calibration) all run through their own thin adapters (their problem,
their step, their stopping rule)."""

from wingopt.estimation.core.least_squares import (
    Damping,
    LeastSquaresProblem,
    LevenbergMarquardt,
    SolverState,
    Stop,
    StoppingPolicy,
    least_squares_fit,
)

__all__ = [
    "Damping",
    "LeastSquaresProblem",
    "LevenbergMarquardt",
    "SolverState",
    "Stop",
    "StoppingPolicy",
    "least_squares_fit",
]
