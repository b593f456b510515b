"""What the wiring checks (:mod:`.wiring`) found: each likely mistake (:class:`Finding`) and the
report of one record's checks (:class:`WiringReport`, ``info["wiring"]``)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

__all__ = ["Finding", "WiringReport", "skipped"]


@dataclass(frozen=True)
class Finding:
    """One likely wiring mistake: ``mistake`` (``"gain"``, ``"offset"``, ``"gain or offset"``,
    ``"swap"``), the sensors, the mean's ratio to its prediction (one sensor off), the chi-square
    its correction removes, and the message."""

    mistake: str
    sensors: tuple[str, ...]
    ratio: float
    evidence: float
    message: str


@dataclass(frozen=True)
class WiringReport:
    """What the wiring checks found (``findings``: empty when none) and how they were run."""

    findings: tuple[Finding, ...]
    prior: str
    baseline_chi2: float
    checked: bool = True
    reason: str = ""

    @property
    def warnings(self) -> list[str]:
        return [f.message for f in self.findings]

    def as_dict(self) -> dict:
        return {
            "checked": self.checked,
            "prior": self.prior,
            "baseline_chi2": self.baseline_chi2,
            "findings": [dataclasses.asdict(f) for f in self.findings],
            **({"reason": self.reason} if self.reason else {}),
        }


def skipped(reason: str) -> WiringReport:
    """The report of checks that did not run, and why."""
    return WiringReport((), "", float("nan"), checked=False, reason=reason)
