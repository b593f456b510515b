"""Settings of the whole-record estimator (:func:`~.estimator.identify_record`) and of the steady
records' estimator it routes to (:func:`~.steady_estimator.steady_identify`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from wingopt.errors import InputError
from wingopt.estimation.core.load_model import GustAmplitude
from wingopt.estimation.options import option
from wingopt.problem.membrane import IdentificationSettings

__all__ = ["RecordSettings", "LOAD_MODELS", "MEMBRANE_MODELS"]

LOAD_MODELS = ("auto", "constant", "gust")
MEMBRANE_MODELS = ("berger", "fvk")
_LOAD_MODEL = {"varying": "gust"}
"""The identification option's name of a load model -> this estimator's (a gust amplitude)."""


@dataclass(frozen=True)
class RecordSettings:
    """Settings of :func:`identify_record`.

    Attributes
    ----------
    modes : int
        Modes of the modal model (lowest at the file's prestrain).
    state_modes : int
        Modes whose initial displacement and velocity are unknowns (the others start at the prior
        mean: they decay within a few ms).
    shapes : int
        Load shapes (smoothest of ``Lam``, zero on the frame).
    edge_shapes : int
        Free-edge load shapes more (:class:`~.load_model.LoadShapes`): loads that act up to the frame.
    record : {"auto", "transient", "steady"}
        ``steady``: a loaded wing in steady flow, no transient: the sensors' mean is fitted with the
        static membrane (:mod:`.steady_estimator`); ``transient``: the whole time series; ``auto``:
        ``steady`` when the record has no transient (:func:`~.steady_estimator.is_steady`).
    frame : {"auto", "off"}
        ``auto``: also fit the prior whose load acts up to the frame and weigh the two by their
        evidence (:mod:`.frame_check`); ``off``: the shapes as given.
    membrane : {"auto", "nonlinear", "linear"}
        ``nonlinear``: the Berger model; ``linear``: the same estimator with the deflection's own
        stretch left out; ``auto``: both are fitted (constant load) and the one with the smaller
        chi-square (same number of unknowns: the likelihood ratio) is kept.
    free, prestrain_rel, damping_rel :
        Free parameters and priors (see :class:`ParameterPrior`); ``None``: the problem file's.
    load_model : {"auto", "constant", "gust"}
    gust : GustAmplitude
        Time scale (knot spacing, s) and acceleration prior of the gust amplitude.
    substeps, substep_s :
        Integration sub-steps per sample: at least ``substeps`` and at most ``substep_s`` seconds
        each (the tension oscillates at twice the first frequency, 164 Hz: at 300 Hz data 7
        sub-steps are used).
    segment_s : float
        Segment length (s) of the misfit report.
    stretch_gain : float
        Factor on the deflection's own stretch (1: Berger, the default and what was measured;
        about 1.45 matches the FvK membrane's mean stiffening at 200 Pa). Berger model only.
    membrane_model : {"berger", "fvk"}
        The nonlinear model: ``berger`` (uniform tension following the mean stretch) or ``fvk``
        (Föppl–von Kármán's exact cubic stiffness on the ``cubic_modes`` lowest modes,
        built on the estimator's mesh by :func:`~wingopt.membrane.forward.modal_model`).
    cubic_modes : int
        Modes with FvK's cubic stiffness (``membrane_model="fvk"``).
    spectrum_bin_hz : float
        Width of the spectral bins of a steady record's buffeting fit (Hz; :mod:`.spectra`).
    max_total_iter : int
        A transient record's work budget: Levenberg–Marquardt iterations of all its fits together
        (the main fit; the alternatives: linear membrane, gust, frame prior; the prior check's and
        the tension profile's refits). Measured (FvK truth, 1 s at 1 kHz) before the early stops and
        the short start (:mod:`.stopping`, :func:`.start.short_start`): L2 25, LE 17, L1 51, L3 143
        (its prior check and frame prior; 35 since the frame prior resolves its conflict first,
        :mod:`.frame_check`); 4.6 s of white noise 80. With them L1 takes 3. The fits stop there, the
        alternatives left are named, and the result says so (``info["budget"]``, a warning).
    stop_early : bool
        Stop a fit that stalls far from converging, and the frame prior's fit once the evidence has
        decided against it (:mod:`.stopping`: deterministic, by chi-squares and iteration counts;
        a stalled fit stays flagged not converged and its band is widened). ``False``: every fit
        runs to the solver's own test or ``max_iter`` (as before issue 26's speed work).
    cpu_s : float or None
        A CPU-second budget on top, for a hard limit beside the wing (``None``: none; CPU time is
        machine-dependent, so it is not the default: the same record would give another answer).
    declaration : IdentificationSettings or None
        What the problem file declares for identification (its ``[identification]``: noise, initial
        load and shape, parameter priors, pressure prior), filled by the builder from the problem
        (:func:`~wingopt.estimation.declaration.with_declaration`; ``None`` until then); a caller
        may give its own. The fits read it here, never the problem.
    """

    modes: int = field(default=48, metadata=option("modes"))
    state_modes: int = 12
    substeps: int = 2
    substep_s: float = 0.5e-3
    shapes: int = 15
    edge_shapes: int = 0
    frame: str = "auto"
    record: str = "auto"
    membrane: str = "auto"
    free: tuple[str, ...] | None = None
    prestrain_rel: float | None = None
    damping_rel: float | None = None
    load_model: str = field(
        default="auto", metadata=option("load_model", lambda v: {"load_model": _LOAD_MODEL.get(v, v)})
    )
    gust: GustAmplitude = field(default_factory=GustAmplitude)
    segment_s: float = 0.05
    max_iter: int = 40
    kappa: float = 1.0
    prior_power: float = 1.0
    stretch_gain: float = 1.0
    membrane_model: str = "berger"
    cubic_modes: int = 16
    spectrum_bin_hz: float = 2.0
    max_total_iter: int = 160
    stop_early: bool = True
    cpu_s: float | None = None
    declaration: IdentificationSettings | None = None

    def __post_init__(self) -> None:
        if self.membrane_model not in MEMBRANE_MODELS:
            raise InputError(f"membrane_model = {self.membrane_model!r}: expected one of {', '.join(MEMBRANE_MODELS)}")
        if self.membrane not in ("auto", "nonlinear", "linear"):
            raise InputError(f"membrane = {self.membrane!r}: expected auto, nonlinear or linear")
        if self.record not in ("auto", "transient", "steady"):
            raise InputError(f"record = {self.record!r}: expected auto, transient or steady")
        if self.frame not in ("auto", "off"):
            raise InputError(f"frame = {self.frame!r}: expected auto or off")
        n = self.max_total_iter
        if isinstance(n, bool) or not (isinstance(n, int) and n > 0):
            raise InputError(f"max_total_iter = {self.max_total_iter!r}: expected a positive number of iterations")
        if self.cpu_s is not None and not (self.cpu_s > 0):
            raise InputError(f"cpu_s = {self.cpu_s!r}: expected CPU seconds > 0, or None")
        if not (self.spectrum_bin_hz > 0):
            raise InputError(f"spectrum_bin_hz = {self.spectrum_bin_hz!r}: expected a positive width (Hz)")
        if self.load_model not in LOAD_MODELS:
            raise InputError(f"load_model = {self.load_model!r}: expected one of {', '.join(LOAD_MODELS)}")

    def replace(self, **kw) -> RecordSettings:
        return dataclasses.replace(self, **kw)
