"""What every estimator shares, whatever its record or model.

* :mod:`.least_squares` — the one nonlinear least-squares solver (Levenberg–Marquardt) that the
  moving-horizon windows and the record fits (transient, steady, calibration) all run through
  their own thin adapters (their problem, their step, their stopping rule);
* :mod:`.load_model` — the load shapes and their smoothness prior, with a gust-following amplitude;
* :mod:`.record_problem`, :mod:`.record_fit` — a record's unknowns, priors, residuals and Jacobian,
  and its adapter to the solver (budget, fit);
* :mod:`.record_settings` — the settings of the record fits;
* :mod:`.start` — the record fits' start-up (modal model, initial state prior, amplitude scan);
* :mod:`.adequacy` — chi-square per datum and per segment, the flag and the band factor;
* :mod:`.prior_check`, :mod:`.frame_check` — the evidence between load priors;
* :mod:`.model_form` — the modal FvK model's prestrain model-form term;
* :mod:`.result` — :class:`~.result.IdentificationResult`, what every estimator returns;
* :mod:`.diagnostics` — :class:`~.diagnostics.Diagnostics`, what every estimator says of its
  answer (warnings, adequacy, convergence, steady lift, parameters), typed;
* :mod:`.noise` — the sensors' noise level from the data, and the one precedence rule;
* :mod:`.sanity` — a record's and a sensor layout's sanity (refusals and warnings);
* :mod:`.load_space` — the load bases (fixed edge, free);
* :mod:`.regularization`, :mod:`.lambda_rules` — the Tikhonov weight chosen from the data, and
  the rules' one registry;
* :mod:`.distributions` — the chi-square tail the misfit tests use.
"""

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
