"""Priors on the load for sensor design, and the smooth random loads drawn from them.

Two Gaussian priors on the load coefficients ``f`` (deflection basis, zero on the edges):

* **Tikhonov** (the estimator's own): precision ``lambda Lam`` with ``Lam = ∫ (f_xx^2 + f_yy^2)``.
  Its scale ``lambda`` is the estimator's: the data-only rule picks it relative to the data's
  information, so the design uses the value the rule gives (emulated in
  :mod:`wingopt.design.risk`) and the linear criteria take it as a parameter.
* **Gaussian process**: a stationary squared-exponential covariance of the pressure,
  ``k(r) = s^2 exp(-r^2 / (2 l^2))`` (length scale ``l``, default 0.3 of the chord), carried to
  the coefficients by the L2 projection, ``Cov f = M^-1 K M^-1`` with ``K_ij = ∫∫ phi_i k phi_j``.

Both are mapped to the modal load ``u = B f`` the data see: ``Cov u = B Cov f B^T``.
:func:`smooth_loads` draws pressures from the same GP family (random Fourier features: analytic
callables, so the protocol projects them exactly like the named loads).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from wingopt.errors import InputError
from wingopt.fe import Cells
from wingopt.membrane import MembraneModel, PressureLoad

__all__ = ["LoadPrior", "tikhonov_prior", "gp_prior", "smooth_loads", "edge_loads", "leading_edge_suction", "PRIORS"]

PRIORS = ("tikhonov", "gp")


@dataclass(frozen=True, eq=False)
class LoadPrior:
    """A Gaussian prior ``f ~ N(0, cov)`` on the load coefficients, with its name and parameters."""

    name: str
    cov: np.ndarray  # (n_f, n_f)
    params: dict

    def modal_cov(self, input_matrix: np.ndarray) -> np.ndarray:
        """``Cov u = B Cov f B^T`` (symmetrised)."""
        P = input_matrix @ self.cov @ input_matrix.T
        return 0.5 * (P + P.T)


def tikhonov_prior(model: MembraneModel, lam: float) -> LoadPrior:
    """``f ~ N(0, (lam Lam)^-1)``: the estimator's smoothness term read as a prior."""
    if not (np.isfinite(lam) and lam > 0):
        raise InputError(f"lambda = {lam!r}: expected a positive Tikhonov weight")
    L = model.regularizer.toarray()
    cov = sla.inv(lam * L)
    return LoadPrior("tikhonov", 0.5 * (cov + cov.T), {"lambda": float(lam)})


def _quadrature(model: MembraneModel, order: int = 3):
    sp_ = model.space
    cells = sp_.cells()
    x, y, w = Cells.quadrature(cells, order)
    return x.ravel(), y.ravel(), w.ravel()


def gp_prior(model: MembraneModel, length_scale: float, std: float = 1.0) -> LoadPrior:
    """Squared-exponential GP on the pressure, projected to the coefficients (``M^-1 K M^-1``).

    ``length_scale`` in metres; ``std`` the pointwise standard deviation (Pa).
    """
    if not (np.isfinite(length_scale) and length_scale > 0):
        raise InputError(f"length_scale = {length_scale!r}: expected a positive length (m)")
    x, y, w = _quadrature(model)
    Phi = model.space.basis_matrix(x, y).toarray() * w[:, None]  # (nq, n): phi_i(x_q) w_q
    d2 = (x[:, None] - x[None, :]) ** 2 + (y[:, None] - y[None, :]) ** 2
    K = std**2 * Phi.T @ np.exp(-0.5 * d2 / length_scale**2) @ Phi
    Minv = sla.inv(model.gram.toarray())
    cov = Minv @ K @ Minv
    return LoadPrior("gp", 0.5 * (cov + cov.T), {"length_scale": float(length_scale), "std": float(std)})


def smooth_loads(
    width: float,
    height: float,
    count: int,
    seed: int,
    length_scale: float | None = None,
    mean: float = 1.0,
    spread: float = 0.5,
    amplitude: float = 200.0,
    features: int = 64,
) -> list[PressureLoad]:
    """``count`` random pressures ``A (mean + spread g(x, y))`` with ``g`` a unit-variance SE-GP draw.

    ``g`` is approximated by ``features`` random Fourier features (frequencies ``N(0, 1/l^2)``),
    which makes each draw an analytic callable. Default ``l`` is 0.3 of the chord. The mean keeps
    the net lift positive, so the protocol's sign prior (+) applies; the pressure is not zero on
    the edges (the estimator's fixed-edge space carries a representation error, as for L3).
    """
    if count < 1:
        raise InputError(f"count = {count!r}: expected at least one load")
    ell = 0.3 * width if length_scale is None else length_scale
    rng = np.random.default_rng(seed)
    out = []
    for k in range(count):
        om = rng.standard_normal((features, 2)) / ell
        ph = rng.uniform(0, 2 * np.pi, features)
        a = rng.standard_normal(features)

        def pressure(x, y, om=om, ph=ph, a=a):
            arg = x[..., None] * om[:, 0] + y[..., None] * om[:, 1] + ph
            g = np.sqrt(2.0 / features) * (np.cos(arg) @ a)
            return amplitude * (mean + spread * g)

        out.append(PressureLoad(f"smooth{seed}-{k}", pressure, f"GP draw l = {ell:.3g} m, seed {seed}, #{k}"))
    return out


def leading_edge_suction(width: float, height: float, amplitude: float = 200.0, decay: float = 0.2) -> PressureLoad:
    """A leading-edge suction peak: ``A exp(-x / (decay W)) sin(pi y / L)`` (largest at x = 0)."""

    def pressure(x, y):
        return amplitude * np.exp(-x / (decay * width)) * np.sin(np.pi * y / height)

    return PressureLoad("leading-edge", pressure, f"{amplitude:g} exp(-x/({decay:g} W)) sin(pi eta)")


def edge_loads(
    width: float,
    height: float,
    count: int,
    seed: int,
    decay: tuple[float, float] = (0.1, 0.4),
    amplitude: float = 200.0,
) -> list[PressureLoad]:
    """``count`` random edge-heavy pressures ``A exp(-d / (delta D)) (1 + 0.5 g(x, y))``.

    ``d`` is the distance from one of the four frame edges (drawn uniformly), ``D`` the membrane's
    size across that edge, ``delta`` uniform in ``decay`` and ``g`` a unit-variance SE-GP draw of
    length 0.2 chord. A generic family of what the smooth draws miss (an edge peak, a leading- or
    trailing-edge suction): large where the fixed-edge load space cannot follow, not zero on the frame.
    """
    if count < 1:
        raise InputError(f"count = {count!r}: expected at least one load")
    rng = np.random.default_rng(seed)
    g = smooth_loads(width, height, count, seed + 7919, 0.2 * width, mean=0.0, spread=1.0, amplitude=1.0)
    out = []
    for k in range(count):
        edge, delta = int(rng.integers(4)), float(rng.uniform(*decay))

        def pressure(x, y, edge=edge, delta=delta, g=g[k]):
            d = (x, width - x, y, height - y)[edge]
            return amplitude * np.exp(-d / (delta * (width if edge < 2 else height))) * (1.0 + 0.5 * g(x, y))

        where = ("x = 0", "x = W", "y = 0", "y = L")[edge]
        out.append(PressureLoad(f"edge{seed}-{k}", pressure, f"edge-heavy at {where}, decay {delta:.2f}, seed {seed}"))
    return out
