"""The load of a steady record: a loaded membrane in steady flow (a wind tunnel), no transient.

A tunnel record starts loaded (no release transient to identify the tension from) and fluctuates
about a static state (buffeting). Its information on the steady load is the sensors' mean ``s̄``:
four numbers. They are fitted with the static Föppl–von Kármán membrane by Gauss–Newton on the
chi-square

    |(s̄ - s(z̄(c, e0))) / tau|^2 + |c|^2 + |e0 - e0_prior|^2_prior,    F(z̄; e0) = sum_k c_k p_k

``tau^2 = var(s̄) + (MODEL_FORM s̄)^2``: the mean's own variance (batch means of the record: buffeting
and noise) and a model-form term. The tension enters through the prestrains' prior: the problem
file's (±20 %) or a calibration's (``wingopt calibrate``), so a record without one has its band set
by that prior (and says so). The iterations use the modal FvK model (its static Newton solve is
microseconds; the Jacobian is exact by implicit differentiation, ``F_q dq = du - dk0/de0 q``); its
cubic truncation is 2–3.5 % off the full-order model in the static outputs of a strongly loaded
wing, so the fit is corrected to the full order (defect correction: the full model's outputs at the
modal optimum minus the modal model's are added to the modal model, and the fit repeated).

The sensors are quadratic and blind to the sign: a load and its negative, and a load and one with
some lobes flipped, can fit equally. The fit starts from the prior sign's amplitude and from the
first antisymmetric shape flipped; the default's load priors (a pressure that may act up to the
frame; the thin-airfoil shapes: :mod:`.steady_estimator`) are each fitted; the answers are weighed by
their Laplace evidence: what the record cannot tell apart stays in the band.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from wingopt.errors import InputError, SolverError
from wingopt.estimation.core.load_model import LoadShapes
from wingopt.estimation.core.record_fit import Fit, levenberg_marquardt
from wingopt.estimation.core.record_problem import ParameterPrior
from wingopt.estimation.core.start import modal_model
from wingopt.membrane.forward import FullStructure, full_model
from wingopt.membrane.model import MembraneModel
from wingopt.membrane.parameters import MembraneParameters

__all__ = ["SteadyData", "SteadyProblem", "steady_data", "MODEL_FORM", "BATCHES"]

log = logging.getLogger(__name__)

MODEL_FORM = 0.01
"""Relative model-form std of the static sensor outputs (the estimator's mesh and the sensor model
against the truth's; measured 25x13 against 49x25 on the tunnel load: below 0.5 %)."""

MODES, CUBIC_MODES = 10**9, 30
"""The modal model of the iterations: every mode of the mesh (a load that peaks at the frame excites
the high ones statically), the lowest 16 with FvK's cubic stiffness (the realistic estimator's)."""

DEFECT_TOL = 0.05
"""The full-order correction stops when it moves every output by less than this fraction of tau."""

BATCHES = 20
"""Batches of the record whose means give the variance of the mean (buffeting is correlated over a
few ms; 20 batches of a 1.5 s record are 75 ms long)."""


@dataclass(frozen=True)
class SteadyData:
    """The mean sensor outputs of a steady record and their standard error."""

    mean: np.ndarray
    std_error: np.ndarray
    fluctuation: np.ndarray
    samples: int


def steady_data(values: np.ndarray) -> SteadyData:
    """Mean, its standard error (batch means) and the RMS fluctuation of each sensor (NaN skipped)."""
    y = np.asarray(values, dtype=float)
    mean = np.nanmean(y, axis=0)
    n = np.sum(np.isfinite(y), axis=0)
    nb = max(2, min(BATCHES, int(n.min()) // 5))
    batches = np.array_split(y, nb)
    means = np.array([np.nanmean(b, axis=0) for b in batches])
    se = np.nanstd(means, axis=0, ddof=1) / np.sqrt(nb)
    return SteadyData(mean, se, np.nanstd(y, axis=0), int(n.min()))


@dataclass(eq=False)
class SteadyProblem:
    """The static least-squares problem of a steady record (interface of :func:`levenberg_marquardt`).

    Unknowns (scaled: every prior is ``N(0, 1)``): the load-shape coefficients ``c`` and the free
    prestrains.
    """

    model: MembraneModel
    shapes: LoadShapes
    data: SteadyData
    prior: ParameterPrior
    model_form: float = MODEL_FORM
    _z: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self.pars = tuple(n for n in self.prior.free if n.startswith("prestrain"))
        self.defect = np.zeros(self.data.mean.size)

    @cached_property
    def fvk(self) -> FullStructure:
        fvk = full_model(self.model, "fvk")
        fvk._inplane  # noqa: B018 - factorised once: the copies with other prestrains share it
        return fvk

    @cached_property
    def modal(self):
        return modal_model(self.model, "fvk", min(MODES, self.model.n), 1e-3, 1, 1.0, CUBIC_MODES)

    @cached_property
    def forces(self) -> np.ndarray:
        """Modal force of each (scaled) shape ``(m, K)``."""
        return self.shapes.modal_forces(self.modal.shapes).T * self.shapes.prior_std[None, :]

    @property
    def dim(self) -> int:
        return self.shapes.count + len(self.pars)

    @cached_property
    def tau(self) -> np.ndarray:
        d = self.data
        return np.sqrt(d.std_error**2 + (self.model_form * np.abs(d.mean)) ** 2)

    @cached_property
    def prior_matrix(self) -> np.ndarray:
        R = np.eye(self.dim)
        r = self.prior.correlation
        if r and len(self.pars) == 2:
            L = np.linalg.cholesky(np.array([[1.0, r], [r, 1.0]]))
            i = self.shapes.count
            R[i:, i:] = np.linalg.inv(L)
        return R

    def physical(self, theta: np.ndarray) -> tuple[np.ndarray, MembraneParameters]:
        """Shape coefficients ``c`` and the membrane parameters of ``theta``."""
        k = self.shapes.count
        c = self.shapes.prior_std * theta[:k]
        e = {}
        for i, name in enumerate(self.pars):
            m, s = self.prior.mean_std(name)
            e[name] = m + s * theta[k + i]
        ex = e.get("prestrain_x", self.prior.mean_std("prestrain_x")[0])
        ey = e.get("prestrain_y", self.prior.mean_std("prestrain_y")[0])
        if min(ex, ey) <= 0:
            raise InputError(f"prestrain ({ex:.3g}, {ey:.3g}): the fit left the physical range")
        return c, MembraneParameters(ex, ey)

    def equilibrium(self, theta: np.ndarray):
        """The full-order static state of ``theta``: ``(fvk, StaticSolution)`` (Newton from the modal state)."""
        c, par = self.physical(theta)
        fvk = self.fvk.with_params(par)
        z0 = self.modal.deflection(self.modal_state(theta)[0]) if self._z is None else self._z
        sol = fvk.static(self.shapes.forces @ c, z0=z0, reuse_tangent=True)
        self._z = sol.z
        return fvk, sol

    def modal_state(self, theta: np.ndarray) -> tuple[np.ndarray, MembraneParameters]:
        _, par = self.physical(theta)
        return self.modal.equilibrium(self.forces @ theta[: self.shapes.count], par), par

    def outputs(self, theta: np.ndarray, full: bool = False) -> np.ndarray:
        """Static sensor outputs of ``theta``: the modal model's plus the defect correction, or the full order's."""
        if full:
            _, sol = self.equilibrium(theta)
            return np.array([sol.z @ (C @ sol.z) for C in self.model.sensors.matrices])
        q, _ = self.modal_state(theta)
        return self.modal.outputs(q[None])[0] + self.defect

    def residuals(self, theta: np.ndarray, jacobian: bool = False):
        theta = np.asarray(theta, dtype=float)
        rp = self.prior_matrix @ theta
        try:
            q, par = self.modal_state(theta)
        except (InputError, ArithmeticError, SolverError) as exc:  # a trial step outside the physical range
            log.debug("steady trial rejected: %s", exc)
            rd = np.full(self.data.mean.size, np.inf)
            return (rd, rp) if not jacobian else (rd, rp, None, None)
        fm = self.modal
        s_ = fm.outputs(q[None])[0] + self.defect
        rd = (self.data.mean - s_) / self.tau
        if not jacobian:
            return rd, rp
        k = self.shapes.count
        rhs = np.zeros((fm.m, self.dim))
        rhs[:, :k] = self.forces
        C, nu = fm.stiffness_c, self.model.problem.material.poisson_ratio
        for i, name in enumerate(self.pars):
            dk0 = C * (fm.kx + nu * fm.ky) if name == "prestrain_x" else C * (fm.ky + nu * fm.kx)
            rhs[:, k + i] = -self.prior.mean_std(name)[1] * dk0 * q
        dq = fm.solve_tangent(q, par, rhs)
        Cq = fm.sensor_products(q[None])[0]  # (p, m)
        J = -2.0 * (Cq @ dq) / self.tau[:, None]
        return rd, rp, J, self.prior_matrix

    def lift(self, theta: np.ndarray) -> float:
        c, _ = self.physical(theta)
        return float(self.shapes.lift_row @ c)

    def lift_gradient(self) -> np.ndarray:
        g = np.zeros(self.dim)
        g[: self.shapes.count] = self.shapes.lift_row * self.shapes.prior_std
        return g


def fit_steady(sp_: SteadyProblem, starts: list[np.ndarray], max_iter: int = 30, corrections: int = 8) -> Fit:
    """The best of Levenberg–Marquardt runs from ``starts`` (by cost), corrected to the full order.

    The corrections repeat until the defect moves the outputs by less than :data:`DEFECT_TOL` of
    their standard error: the answer is then the full-order model's, whatever the modal truncation.
    Where the modal model's sensitivities are far from the full order's (a strongly loaded, slack
    membrane: strains of the order of the prestrain), plain correction overshoots and can cycle
    between two answers on either side of the full-order fit (measured: 1.08 and 2.54 N about
    1.75 N at 4 % prestrain, for ever); a correction that reverses the previous one is relaxed
    (halved, and halved again while they keep reversing), which damps the cycle onto the fixed point.
    A correction that has not settled is said (``Fit.converged`` false, and a log line).
    """
    best = None
    sp_.defect = np.zeros(sp_.data.mean.size)
    for th in starts:
        try:
            f = levenberg_marquardt(sp_, th, max_iter)
        except (InputError, ArithmeticError, SolverError) as exc:
            log.debug("steady start failed: %s", exc)
            continue
        if best is None or f.cost < best.cost:
            best = f
    if best is None:
        raise InputError("steady record: no start of the static fit converged; check the data's units")
    if not corrections:
        return best
    relax, previous, settled = 1.0, None, False
    for _ in range(corrections):
        sp_._z = None
        try:
            step = sp_.outputs(best.theta, full=True) - sp_.outputs(best.theta)
        except (InputError, ArithmeticError, SolverError) as exc:
            log.debug("full-order correction failed: %s", exc)
            break
        settled = bool(np.all(np.abs(step) <= DEFECT_TOL * sp_.tau))
        scaled = step / sp_.tau
        if not settled and previous is not None and scaled @ previous < 0:
            relax = max(0.5 * relax, 1.0 / 16)
        previous = scaled
        sp_.defect = sp_.defect + relax * step
        best = levenberg_marquardt(sp_, best.theta, max_iter)
        if settled:
            break
    if not settled:
        log.info("steady fit: the full-order correction did not settle in %d steps", corrections)
        best = dataclasses.replace(best, converged=False)
    return best


def _antisymmetric(sp_: SteadyProblem) -> int | None:
    """Index of the first load shape that is antisymmetric in x (the other lobe pattern's direction)."""
    W, L = sp_.model.problem.width, sp_.model.problem.height
    x = np.linspace(0.05 * W, 0.95 * W, 9)
    y = np.full_like(x, 0.5 * L)
    space = sp_.shapes.space.space if sp_.shapes.space is not None else sp_.model.space
    for j in range(sp_.shapes.count):
        f = space.evaluate(sp_.shapes.shapes[:, j], x, y)
        if np.abs(f + f[::-1]).max() < 1e-6 * np.abs(f).max():
            return j
    return None


def starts(sp_: SteadyProblem, sign: float) -> list[np.ndarray]:
    """Starts along the smoothest shape (the prior's sign) and along the first x-antisymmetric one,
    each scaled so that the sensors' mean is matched to first order (they are quadratic in the load)."""
    out = []
    for j in (0, _antisymmetric(sp_)):
        if j is None:
            continue
        th = np.zeros(sp_.dim)
        th[j] = sign * 0.5
        rd, _ = sp_.residuals(th)
        s_model = sp_.data.mean - rd * sp_.tau
        th[j] *= np.sqrt(max(np.nansum(sp_.data.mean), 1e-30) / max(np.nansum(s_model), 1e-30))
        out.append(th)
    return out


def evidence(fit: Fit) -> float:
    """Laplace log-evidence (up to the data's normalisation)."""
    return float(-0.5 * fit.cost - 0.5 * np.linalg.slogdet(fit.precision)[1])
