"""Start-up of the nonlinear streaming estimator: the batch fit of the buffered samples, handed to the filter.

The filter's weak point is its start: the prior is far from the answer and the first samples (the
ringing bubble) carry most of what identifies the tension, so linearising at a poor estimate
there biases everything after. The start-up therefore solves the realistic estimator's problem
(:class:`~wingopt.estimation.core.record_problem.RecordProblem`, Levenberg–Marquardt,
:func:`~wingopt.estimation.core.record_fit.levenberg_marquardt`) on the buffered samples, from the
provisional filter's load and parameters, and converts its answer into the filter's mean and
covariance at the last buffered sample: the state is propagated from the fitted initial state
with the exact tangent of the unknowns (``G``, ``P = G Sigma G^T``, ``Sigma`` the fit's posterior
covariance), and so are a declared analog filter's states (:mod:`.output_filter`; the fit models
the filter as the batch's does). From then on the filter continues as the batch would with an
arrival cost. When the fit from the provisional estimate does not fit the data (chi-square per
datum above 1.15, the batch's tolerance) it is also started from the batch's amplitude scan and
the better fit is kept; without a bubble prior the sign is the prior load's (the batch's rule).
"""

from __future__ import annotations

import numpy as np

from wingopt.estimation.core.onset import lead_note, quiet_lead
from wingopt.estimation.core.record_fit import levenberg_marquardt
from wingopt.estimation.core.record_problem import RecordProblem
from wingopt.estimation.core.start import record_filter, scan
from wingopt.estimation.streaming.output_filter import sensor_input

__all__ = ["batch_start", "TOLERANCE"]

TOLERANCE = 0.15
"""The batch's adequacy tolerance on the chi-square per datum (:mod:`wingopt.estimation.core.adequacy`)."""

START_DECREMENT = 0.1
"""Newton decrement at which the start-up solve stops: within ~0.3 posterior sigma of the optimum of
the buffered samples, which every later sample's update refines (the batch stops at 0.01)."""


def batch_start(est, Y: np.ndarray, sigma: np.ndarray, max_iter: int = 20) -> dict:
    """Fit the buffered samples ``Y`` and set ``est.x``, ``est.P`` at the last one; returns diagnostics.

    ``est`` is a :class:`~wingopt.estimation.streaming.nonlinear.NonlinearStreamingEstimator`
    with its prior set (``_D``, ``_prior_state``) and a provisional estimate in ``est.x``.
    """
    bm, m, ms = est.bm, est.m, min(est.settings.state_modes, est.m)
    # a pre-trigger: the fit starts where the motion does
    lead = quiet_lead(Y, sigma, est.dt, est.model.problem.acquisition)
    Y = Y[lead:]
    x_prior, _ = est._prior_state(Y)
    D = est._D
    x_mean = np.concatenate([D[:m] * x_prior[:m], np.zeros(m)])
    t = est.dt * np.arange(Y.shape[0])
    daq = record_filter(est.model.problem)  # the declared analog filter, as the batch fit
    rp = RecordProblem(bm, est.shapes, t, Y, sigma, est.prior, x_mean, D.copy(), None, True, ms, daq=daq)
    sl = rp.slices
    theta0 = np.zeros(rp.dim)
    theta0[sl["c"]] = est.x[est.ls]  # the provisional filter's load and parameters: a start near the optimum
    theta0[sl["par"]] = est.x[est.ps]
    fit = levenberg_marquardt(rp, theta0, max_iter, START_DECREMENT)
    starts = 1
    # not a fit, or a provisional filter that ran through a pre-trigger expecting motion (its load may
    # be the mirror's: L1 after 0.25 s still, -198 %): the batch's start (amplitude scan) too
    if lead or fit.data_cost > (1 + TOLERANCE) * rp.n_data:
        other = levenberg_marquardt(rp, scan(rp, 1.0), max_iter, START_DECREMENT)
        starts = 2
        fit = other if other.cost < fit.cost else fit
    theta, Sigma = fit.theta, fit.covariance
    peak = est.settings.declaration.initial_deflection
    if peak == 0 and est._lift @ theta[sl["c"]] * np.sign(est.initial_load) < 0:
        # sign-blind sensors and no bubble: state and load flip together, the prior load's sign decides
        flip = np.ones(rp.dim)
        flip[sl["x0"]] = flip[sl["c"]] = -1.0
        theta, Sigma = flip * theta, flip[:, None] * Sigma * flip[None, :]
    d = rp.dim
    # the filter's state at sample 0 and its derivative w.r.t. the fit's unknowns
    x = x_prior.copy()
    x[:ms] += theta[:ms]
    x[m : m + ms] = theta[ms : 2 * ms]
    x[est.ls] = theta[sl["c"]]
    x[est.ps] = theta[sl["par"]]
    idx = np.arange(ms)
    dQ, dV = np.zeros((d, m)), np.zeros((d, m))
    dQ[idx, idx] = D[idx]
    dV[ms + idx, idx] = D[m + idx]
    q, v = D[:m] * x[:m], D[m:] * x[m : 2 * m]
    ex, ey, damping, seeds = est._params(x)
    u = x[est.ls] @ est._forces
    C, states = bm.sensor_matrices, est.daq  # the DAQ filter's states go along (None: point samples)
    if states is not None:
        h0 = sensor_input(C, q, v, dQ, dV)
        states.settle(h0)
    for _ in range(Y.shape[0] - 1):
        q, v, dQ, dV = est.fit_sampler.step_tangent(q, v, u, ex, ey, damping, dQ, dV, seeds)
        if states is not None:
            h1 = sensor_input(C, q, v, dQ, dV)
            states.step(h0, h1)
            h0 = h1
    x[:m], x[m : 2 * m] = q / D[:m], v / D[m:]
    est.x = x
    est.G = np.vstack([dQ.T / D[:m, None], dV.T / D[m:, None]])
    est.Sigma = Sigma
    _window_misfit(est, rp, fit.residuals)
    return {
        **({"lead_note": lead_note(lead, t + est.dt * lead)} if lead else {}),
        "startup_iterations": fit.iterations,
        "startup_starts": starts,
        "startup_converged": fit.converged,
        "startup_chi2_per_datum": fit.data_cost / max(rp.n_data, 1),
    }


def _window_misfit(est, rp: RecordProblem, residuals: np.ndarray) -> None:
    """The filter's misfit window filled with the fit's residuals of its last samples."""
    R = np.zeros(rp.y.shape)
    R[rp.valid] = residuals
    n = rp.y.shape[0]
    tail = slice(max(n - est._nis.size, 0), n)
    r2 = (R[tail] ** 2).sum(axis=1)
    est._nis[:] = 0.0
    est._nd[:] = 0
    est._nis[: r2.size] = r2
    est._nd[: r2.size] = rp.valid[tail].sum(axis=1)
    est._ring = r2.size - 1
