"""Research script: priors for edge loads and a data-driven choice between them (issue 5 gaps).

For every (load, noise, seed) and every prior *family* (load space + roughness operator) it runs
the MHE and records, on the first window's lambda path, the Laplace (Gauss–Newton) log evidence
``log p(y | family, lambda)`` next to the misfit, plus the final load and lift errors at the
rule's lambda. Families:

* ``fixed``: the seed's deflection basis (zero on the edges), ``Lam = ∫ f_xx^2 + f_yy^2``.
* ``edge<b>``: free edges, ``Lam_f + b k^4 L_y ∮ f^2`` (the package's free space, ``b = edge_weight``).
* ``matern<r>``: free edges, SPDE/Matérn (nu = 1) precision
  ``∫ (Δf)^2 + 2 kappa^2 |∇f|^2 + kappa^4 f^2`` with ``kappa = sqrt(8) / rho``, ``rho = r * W``.

Nothing here tunes on the truth: the truth is only used to score the final estimates.

Usage (``OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1``)::

    python benchmarks/edge_prior_study.py --seeds 100-104 --families fixed,edge1,matern0.5 \
        --out /tmp/edge/design.jsonl --jobs 2
    python benchmarks/edge_prior_study.py --loads L1 --noise 1 --seeds 100 --families fixed \
        --out /tmp/edge_quick.jsonl --jobs 1   # quickest
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import time

import numpy as np

from wingopt.estimation.core.load_space import LoadSpace, build_load_space
from wingopt.estimation.mhe import MHESettings, MovingHorizonEstimator
from wingopt.fe import DX, DXX, DY, DYY, VALUE, assemble, separable
from wingopt.membrane import MembraneModel, TruthRecord
from wingopt.problem import load_problem
from wingopt.workflows.protocols import simulate_case
from wingopt.workflows.studies import evaluate, noisy_case, protocol_sign


def prior_family_space(model: MembraneModel, family: str) -> LoadSpace:
    """The load space of a family name (see the module docstring)."""
    if family == "fixed":
        return build_load_space(model, "fixed")
    if family.startswith("edge"):
        return build_load_space(model, "free", edge_weight=float(family[4:]))
    if family.startswith("matern"):
        free = build_load_space(model, "free", edge_weight=0.0)
        rho = float(family[6:]) * model.problem.width
        k2 = 8.0 / rho**2
        reg = assemble(
            free.space,
            separable(
                (1.0, DXX, DXX),
                (1.0, DYY, DYY),
                (1.0, DXX, DYY),
                (1.0, DYY, DXX),
                (2 * k2, DX, DX),
                (2 * k2, DY, DY),
                (k2**2, VALUE, VALUE),
            ),
        )
        return LoadSpace(free.kind, free.space, free.gram, free.coupling, reg.tocsr())
    raise ValueError(family)


def laplace_log_evidence(problem, theta, lam) -> dict:
    """Gauss–Newton Laplace log evidence of one window (up to a family-independent constant)."""
    D = problem.scale
    r, J = problem.linearize(theta)
    H0s = D[:, None] * problem.H0 * D[None, :]
    Js = J * D[None, :]
    Hs = Js.T @ Js + H0s
    _, ld_h = np.linalg.slogdet(0.5 * (Hs + Hs.T))
    _, ld_0 = np.linalg.slogdet(0.5 * (H0s + H0s.T))
    chi2 = problem.data_cost(theta)
    # The window drops the constant mu^T P mu of the state prior; restore it so that evidences
    # with different state priors compare (first window: H0's state block is the prior precision).
    k = 2 * problem.reduced.m
    g = problem.g0[:k]
    c0 = float(g @ np.linalg.solve(problem.H0[:k, :k], g))
    prior = problem.prior_cost(theta) + c0
    return {
        "lam": float(lam),
        "chi2": chi2,
        "prior": prior,
        "occam": 0.5 * (ld_h - ld_0),
        "logz": -0.5 * (chi2 + prior) - 0.5 * (ld_h - ld_0),
    }


class _Probe(MovingHorizonEstimator):
    """MHE with a given load space, recording the evidence along the lambda path."""

    def __init__(self, model, settings, load_space):
        super().__init__(model, settings)
        from wingopt.estimation.mhe.model import MHEModel

        self.load_space = load_space
        self.reduced = MHEModel.build(model, load_space, settings.modes)
        self.evidence = []

    def setup(self, *args, **kwargs):  # noqa: D102 - records every point of the lambda path
        from wingopt.estimation.mhe import lambda_path

        plain = lambda_path.path_point

        def point(problem, sol, lam):
            self.evidence.append(laplace_log_evidence(problem, sol.theta, lam))
            return plain(problem, sol, lam)

        lambda_path.path_point = point
        try:
            return super().setup(*args, **kwargs)
        finally:
            lambda_path.path_point = plain


class CleanCases:
    """Noise-free protocol runs (truth 49x25), simulated once per load; :meth:`case` adds seeded noise.

    The estimators are not told the simulated noise level (they estimate it), as with measurements.
    (The package's ``CleanCases`` was retired; this is its protocol, built on ``simulate_case``.)
    """

    def __init__(self, problem) -> None:
        self.problem = problem
        self._clean: dict[str, TruthRecord] = {}

    def case(self, load: str, noise: float, seed: int) -> TruthRecord:
        if load not in self._clean:
            self._clean[load] = simulate_case(self.problem, load, 0.0, None, tell_noise=False)
        return noisy_case(self._clean[load], noise, seed, tell_noise=False)


_W: dict = {}


def _init(problem):
    _W["problem"] = problem
    _W["model"] = MembraneModel.from_problem(problem)
    _W["clean"] = CleanCases(problem)
    _W["spaces"] = {}


def _space(family):
    if family not in _W["spaces"]:
        _W["spaces"][family] = prior_family_space(_W["model"], family)
    return _W["spaces"][family]


def _task(args):
    load, noise, seed, family, lam_fixed, state_prior, oracle = args
    problem, model = _W["problem"], _W["model"]
    case = _W["clean"].case(load, noise, seed)
    sign = protocol_sign(load) * abs(problem.identification.initial_load)
    settings = MHESettings(regularization=lam_fixed, state_prior=state_prior)
    t0 = time.perf_counter()
    est = _Probe(model, settings, _space(family))
    est.setup(case.measurements, initial_load=sign)
    res = est.run()
    # Evidence of the first window at the chosen lambda (re-solved problem at the window start).
    rec = evaluate(case, res, model, family)
    lam_info = est.lambda_info
    out = {
        "load": load,
        "noise": noise,
        "seed": seed,
        "family": family,
        "state_prior": state_prior,
        "lambda": est.lam,
        "natural": lam_info.get("natural_scale"),
        "knee": lam_info.get("knee"),
        "load_error": rec.load_error,
        "lift_error": rec.lift_error,
        "lift": rec.lift,
        "true_lift": rec.true_lift,
        "sign_ok": rec.sign_ok,
        "path": est.evidence,
        "n": int(est._window_problem(0, est.lam).n_data),
        "seconds": time.perf_counter() - t0,
    }
    if oracle:
        scan = []
        for off in np.arange(-2.0, 1.01, 0.5):
            lam = est.lam * 10.0**off
            e2 = _Probe(model, settings.replace(regularization=lam), _space(family))
            e2.setup(case.measurements, initial_load=sign)
            r2 = evaluate(case, e2.run(), model, family)
            scan.append((float(off), r2.load_error, r2.lift_error))
        out["oracle"] = scan
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--loads", default="L1,L2,L3")
    ap.add_argument("--noise", default="1,5", help="percent")
    ap.add_argument("--seeds", default="100-104", help="a-b (inclusive) or comma list")
    ap.add_argument("--families", default="fixed,edge1")
    ap.add_argument("--state-prior", default="1", help="comma list of MHESettings.state_prior values")
    ap.add_argument("--oracle", action="store_true", help="also the errors at rule lambda x 10^(-2..1)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    if "-" in a.seeds:
        lo, hi = (int(x) for x in a.seeds.split("-"))
        seeds = list(range(lo, hi + 1))
    else:
        seeds = [int(x) for x in a.seeds.split(",")]
    tasks = [
        (load, float(n) / 100, s, fam, None, float(sp_), a.oracle)
        for load in a.loads.split(",")
        for n in a.noise.split(",")
        for s in seeds
        for fam in a.families.split(",")
        for sp_ in a.state_prior.split(",")
    ]
    problem = load_problem("membrane")
    with open(a.out, "a") as fh, mp.get_context("fork").Pool(a.jobs, _init, (problem,)) as pool:
        for r in pool.imap_unordered(_task, tasks):
            fh.write(json.dumps(r) + "\n")
            fh.flush()
            if "oracle" in r:
                print("   oracle:", " ".join(f"{o:+.1f}:{e:.4f}" for o, e, _ in r["oracle"]))
            best = max(r["path"], key=lambda p: p["logz"])
            print(
                f"{r['load']} {100 * r['noise']:g}% s{r['seed']} {r['family']:>10} sp {r['state_prior']:g}: "
                f"err {r['load_error']:.4f} "
                f"lift {r['lift_error']:.4f} lam {r['lambda']:.3g} | max logz {best['logz']:.2f} at {best['lam']:.3g}",
                flush=True,
            )


if __name__ == "__main__":
    main()
