"""What ``wingopt compare`` runs: the comparison preset, checked once at construction.

The study (:mod:`wingopt.workflows.comparison`) runs it and the report
(:mod:`wingopt.workflows.comparison_report`) writes its protocol notes; both import it from here.
"""

from __future__ import annotations

import warnings
from dataclasses import InitVar, dataclass

from wingopt.errors import InputError
from wingopt.problem.membrane import MembraneProblem
from wingopt.workflows.protocols import TRUTH_NODES
from wingopt.workflows.studies import METHODS

__all__ = ["LOADS", "JEKF_MODES", "ComparisonPreset"]

LOADS = ("L1", "L2", "L3")
"""The load cases of the comparison."""

JEKF_MODES = 60
"""The JEKFs' default order in ``compare`` (the demo's): their lowest 60 of the estimator's modes."""


@dataclass(frozen=True)
class ComparisonPreset:
    """What ``wingopt compare`` runs (the defaults are the command's).

    ``seeds`` noise seeds from ``first_seed`` for the table (``table=False``: none) with
    ``methods``, the MHE's oracle lambda unless ``oracle=False``; the MHE's sign and band study over
    ``sign_seeds`` seeds at 5 % noise; the consistency study; the MHE's load space and state prior
    (:class:`~wingopt.estimation.options.IdentifyOptions`); the truth's mesh; the JEKFs' order
    ``jekf_modes`` (their lowest modes only, :data:`JEKF_MODES` by default, as the demo's; ``None``:
    every mode, the exact filter, ~10x the CPU time). ``noise_fractions``: the noise levels as
    FRACTIONS of each sensor's peak (0.01 = 1 %); the former keyword ``noises`` warns (:class:`FutureWarning`).
    """

    loads: tuple[str, ...] = LOADS
    noise_fractions: tuple[float, ...] = (0.01, 0.05)
    seeds: int = 5
    first_seed: int = 0
    methods: tuple[str, ...] = METHODS
    table: bool = True
    oracle: bool = True
    sign_seeds: int = 0
    consistency: bool = False
    load_space: str = "fixed"
    state_prior: str = "1"
    truth_mesh: tuple[int, int] = TRUTH_NODES
    jekf_modes: int | None = JEKF_MODES
    noises: InitVar[tuple[float, ...] | None] = None

    def __post_init__(self, noises: tuple[float, ...] | None) -> None:
        from wingopt.resources import LIMITS, check_count

        if noises is not None:
            msg = "ComparisonPreset(noises=...) is deprecated, use noise_fractions (the same fractions)"
            warnings.warn(msg, FutureWarning, stacklevel=3)
            object.__setattr__(self, "noise_fractions", tuple(noises))
        if self.jekf_modes is not None and (
            isinstance(self.jekf_modes, bool) or not isinstance(self.jekf_modes, int) or self.jekf_modes < 1
        ):
            raise InputError(f"jekf-order = {self.jekf_modes!r}: expected a positive number of modes or 'full'")
        if self.jekf_modes is not None:
            check_count("jekf-order", self.jekf_modes, "modes")

        for name, given, words in (
            ("loads", self.loads, ", ".join(LOADS)),
            ("methods", self.methods, ", ".join(METHODS)),
            ("noise", self.noise_fractions, "noise levels in percent, e.g. 1,5"),
        ):
            if self.table and not given:
                raise InputError(f"{name} = {','.join(map(str, given))!r}: expected at least one ({words})")
        if not self.table and not self.sign_seeds and not self.consistency:
            raise InputError(
                "table = no: nothing left to run; give --n-sign-seeds N or --consistency, or keep the table"
            )
        for name, given, known in (("loads", self.loads, LOADS), ("methods", self.methods, METHODS)):
            for v in given:
                if v not in known:
                    raise InputError(f"{name}: {v!r}: expected some of {', '.join(known)}")
        if self.seeds < 1 or self.first_seed < 0 or self.sign_seeds < 0:
            raise InputError("seeds: expected a positive integer (first-seed, sign-seeds: non-negative)")
        check_count("seeds", self.seeds)
        check_count("sign-seeds", self.sign_seeds, "seeds")
        tasks = len(self.loads) * len(self.noise_fractions) * self.seeds * len(self.methods) * (1 if self.table else 0)
        tasks += len(self.loads) * self.sign_seeds
        if tasks > LIMITS["tasks"]:
            raise InputError(
                f"seeds = {self.seeds}: {tasks} study tasks (loads x noise x seeds x methods), more than the limit of "
                f"{LIMITS['tasks']}; split the study (--first-seed)"
            )

    def runs(self) -> tuple[list[tuple], list[tuple]]:
        """The table's runs and the sign study's, as (load, noise, seed, method)."""
        seeds = range(self.first_seed, self.first_seed + self.seeds)
        noises = self.noise_fractions
        table = [(ld, nz, sd, m) for ld in self.loads for nz in noises for sd in seeds for m in self.methods]
        sign = [(ld, 0.05, sd, "mhe") for ld in self.loads for sd in range(self.sign_seeds)]
        return (table if self.table else []), sign

    def title(self, problem: MembraneProblem) -> str:
        """The heading of the comparison table."""
        last = self.first_seed + self.seeds - 1
        seeds = f" ({self.first_seed}–{last})" if self.first_seed else ""
        prior = "" if self.state_prior == "1" else ", state prior " + self.state_prior
        order = ""
        if any(m.startswith("jekf") for m in self.methods):
            order = ", JEKF " + ("exact (every mode)" if self.jekf_modes is None else f"{self.jekf_modes} modes")
        return (
            f"### Final errors, mean (min–max) over {self.seeds} noise seeds{seeds}; "
            f"truth {self.truth_mesh[0]}x{self.truth_mesh[1]}, "
            f"estimator {problem.nodes[0]}x{problem.nodes[1]}, MHE load space {self.load_space}{prior}{order}"
        )
