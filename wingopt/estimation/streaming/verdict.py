"""The stream's verdict on its whole record: a filter that went on from a fit that misfits, or whose
windows misfit through much of the record, is flagged to its end, not only while a window misfits.

The per-sample flag (:class:`~wingopt.estimation.core.result.Estimate` ``adequate``) tests the latest
window only. A filter with a constant load carries everything it saw in its mean: a gust it could
not follow, or a start-up or reset whose batch fit did not fit its samples, biases the answer after
the windows fit again, with a narrow band (fuzz record #21, FvK truth: a sharp leading-edge load,
a 30 % gust at 0.4 s, a reset from a batch fit at chi-square 15.9 per datum; the window misfit at
185 of its 351 tracking samples, then fitted again; the stream ended `converged` at 0.56 ± 0.27 N
for 1.82 N, 4.7 bands). :class:`Verdict` keeps what the
stream can check without the truth, and the stream's estimates are flagged while any holds:

* a batch fit that the filter went on from (the start-up's, a reset's) whose chi-square per datum
  is above ``1 + TOLERANCE`` (the batch's own adequacy tolerance): flagged from then on;
* the window misfit at more than :data:`MISFIT_FRACTION` of the tracking samples so far.

Each is said once in the stream's warnings, with what it means for the answer.
"""

from __future__ import annotations

__all__ = ["Verdict", "MISFIT_FRACTION"]

MISFIT_FRACTION = 0.1
"""Share of the tracking samples whose window misfit beyond which the record is flagged. A record
the filter's model explains is flagged in a window at the test's false-alarm rate (1e-3 family-wise
per record, :data:`~wingopt.estimation.mhe.consistency.SIGNIFICANCE`); a tenth of the record is a
model that did not explain it (a gust, a load that moves, a start the filter never recovered from)."""


class Verdict:
    """What the stream knows about its whole record (module docstring); ``ok`` while nothing flags it.

    Parameters
    ----------
    tolerance : float
        The batch's adequacy tolerance on a fit's chi-square per datum (``0.15``).
    """

    def __init__(self, tolerance: float) -> None:
        self.tolerance = float(tolerance)
        self.tracking = 0
        self.misfit = 0
        self.poor_fits: list[dict] = []

    def fitted(self, chi2_per_datum: float, samples: int, what: str) -> None:
        """The filter goes on from a batch fit of ``samples`` samples (``what``: start-up, reset)."""
        if chi2_per_datum > 1.0 + self.tolerance:
            self.poor_fits.append({"fit": what, "samples": int(samples), "chi2_per_datum": float(chi2_per_datum)})

    def sample(self, window_ok: bool) -> None:
        """One tracking sample's window test."""
        self.tracking += 1
        self.misfit += not window_ok

    @property
    def misfit_share(self) -> float:
        return self.misfit / self.tracking if self.tracking else 0.0

    @property
    def ok(self) -> bool:
        return not self.poor_fits and self.misfit_share <= MISFIT_FRACTION

    def warnings(self) -> list[str]:
        out = []
        if self.poor_fits:
            first = self.poor_fits[0]
            out.append(
                f"the {first['fit']}'s batch fit does not fit its {first['samples']} samples (chi-square "
                f"{first['chi2_per_datum']:.3g} per datum; {len(self.poor_fits)} such fit(s)): the filter went on from "
                "a poor start, and its answer may be far off with a narrow band: flagged (run the batch identify on "
                "the stored record)"
            )
        if self.misfit_share > MISFIT_FRACTION:
            out.append(
                f"the window misfit at {self.misfit} of the {self.tracking} tracking samples "
                f"({self.misfit_share:.0%}, more than {MISFIT_FRACTION:.0%}): the filter's constant load does not "
                "explain the record, and what it could not follow stays in its answer: flagged"
            )
        return out

    def as_dict(self) -> dict:
        return {
            "ok": self.ok,
            "tracking_samples": self.tracking,
            "misfit_samples": self.misfit,
            "poor_fits": list(self.poor_fits[-20:]),
        }
