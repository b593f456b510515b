"""The demo's real-membrane case (issue 11): FvK truth with the prestrain off the file's.

The seed's linear MHE beside the realistic estimator with the cubic modal Föppl–von Kármán
membrane (the default of ``wingopt identify --data``), with misfit and band in the report.
"""

from __future__ import annotations

from pathlib import Path

from wingopt.results.report import Report

__all__ = ["REAL_PRESTRAIN", "REAL_MODELS", "run_real_membrane", "real_rows", "real_section"]

REAL_PRESTRAIN = (0.06, 0.045)
"""Prestrain of the demo's real membrane (x, y): +20 % and -10 % off the file's 0.05, unequal."""

REAL_MODELS = ("linear", "fvk")
"""The real-membrane case: the seed's linear MHE beside the realistic estimator with the FvK membrane."""


def run_real_membrane(membrane, cfg, out: Path, stage=None) -> dict:
    """Identify L1 on FvK truth with each of :data:`REAL_MODELS`; outputs under ``out/MODEL``.

    ``stage``: called with each run's label as it starts (the demo's progress lines)."""
    from wingopt.workflows.identify import identify, write_identify_outputs

    summary = {}
    for model in REAL_MODELS:
        if stage is not None:
            stage(f"real membrane: {model}")
        run = identify(
            membrane,
            load="L1",
            noise_percent=100 * cfg.noise_fraction,
            seed=cfg.seed,
            model=model,
            truth="fvk",
            truth_prestrain=cfg.real_prestrain,
            truth_nodes=cfg.real_truth_nodes,
            t_end=cfg.identify_t_end,
        )
        write_identify_outputs(run, out / model)
        summary[model] = run.summary()
    return summary


def real_rows(summary: dict) -> list[list[str]]:
    """Table rows of the real-membrane case (one per model)."""
    rows = []
    names = {"linear": "linear MHE (seed protocol)", "fvk": "realistic, FvK membrane"}
    for model, s in summary.get("real_membrane", {}).items():
        err, std, true = s["lift_N"] - s["true_lift_N"], s.get("lift_std_N"), s["true_lift_N"]
        covers = std is not None and abs(err) <= std
        chi2 = s.get("chi2_per_datum")
        rows.append(
            [
                names.get(model, model),
                f"{s['lift_N']:.4f} ({true:.4f})",
                f"{100 * err / abs(true):+.1f} %",
                "–" if std is None else f"±{100 * std / abs(true):.1f} %",
                str(bool(covers)),
                "–" if chi2 is None else f"{chi2:.2f}",
                str(s.get("model_adequate")),
                f"{s['load_error']:.3f}",
                f"{s['wall_s']:.1f}",
            ]
        )
    return rows


def real_section(rep: Report, tmp: Path, summary: dict, cfg) -> None:
    """The report's section 2b."""
    ex, ey = cfg.real_prestrain
    nx, ny = cfg.real_truth_nodes
    rep.heading("2b. A real membrane: large deflection, prestrain off the file's")
    rep.paragraph(
        f"Truth: the Föppl–von Kármán membrane (in-plane displacements, nonlinear strains) on {nx}x{ny}, prestrain "
        f"({ex:g}, {ey:g}) where the problem file says 0.05 in both directions, L1 from the 1 cm bubble, "
        f"{cfg.identify_t_end:g} s at 1 ms, {100 * cfg.noise_fraction:g} % noise. First row: the seed's linear MHE "
        "(file's tension); second: the realistic estimator with the cubic modal FvK membrane, prestrains and "
        "damping identified (the default of wingopt identify --data). The band is 1 sigma; chi-square per "
        "datum near 1 means the data fit the model; a misfit flag widens the band."
    )
    rep.table(
        [
            "estimator",
            "lift (true) N",
            "lift error",
            "band",
            "covers",
            "chi2/datum",
            "adequate",
            "field error",
            "wall (s)",
        ],
        real_rows(summary),
        "Final lift and relative L2 load error on the real membrane",
    )
    fvk = summary["real_membrane"].get("fvk", {})
    if fvk.get("parameters"):
        par, std, true = fvk["parameters"], fvk.get("parameters_std", {}), fvk.get("true_parameters", {})
        rep.table(
            ["parameter", "estimate", "1 sigma", "true"],
            [
                [k, f"{v:.4g}", f"{std.get(k, float('nan')):.2g}", f"{true.get(k, float('nan')):.4g}"]
                for k, v in par.items()
            ],
            "Model parameters identified by the realistic estimator",
        )
    for model in REAL_MODELS:
        d = tmp / "real-membrane" / model
        for name, cap in (
            ("lift.png", "lift history (1-sigma band)"),
            ("misfit.png", "misfit per segment"),
            ("load_field.png", "estimated vs true load"),
        ):
            if (d / name).exists():
                rep.figure(d / name, f"real membrane, {model}: {cap}")
