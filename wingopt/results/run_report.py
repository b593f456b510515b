"""``report.html`` of one ``identify`` or ``calibrate`` run: one self-contained file a lab can archive.

Built on :class:`~wingopt.results.report.Report` (inline CSS, figures as base64 PNG, no scripts):
the inputs with their SHA-256, the route, where the tension came from, the warnings, the numbers
and the figures the run wrote, then the provenance (version, time, command line, platform).
"""

from __future__ import annotations

from pathlib import Path

from wingopt.results.report import Report

__all__ = ["identify_report", "calibration_report"]


def _inputs(rep: Report, prov: dict) -> None:
    rows = [(r["option"], r["path"], r["bytes"], r["sha256"]) for r in prov.get("inputs", [])]
    if rows:
        rep.table(["input", "absolute path", "bytes", "SHA-256"], rows, "Inputs")
    else:
        rep.paragraph("Inputs: none read from files (the record was given in memory or simulated).", "note")


def _provenance(rep: Report, prov: dict, problem: dict | None) -> None:
    rep.heading("Provenance")
    rows = [
        ("package", f"wingopt {prov.get('version')}"),
        ("time (UTC)", prov.get("time_utc")),
        ("command line", " ".join(prov.get("command_line", []))),
        ("working directory", prov.get("working_directory")),
        ("python / platform", f"{prov.get('python')} / {prov.get('platform')}"),
        ("CPUs / BLAS threads", f"{prov.get('cpus')} / {_blas(prov.get('blas_threads') or {})}"),
    ]
    if problem:
        rows += [
            ("problem", f"{problem.get('name')} ({problem.get('file')})"),
            ("problem file SHA-256", problem.get("file_sha256")),
            ("problem as run SHA-256", problem.get("as_run_sha256")),
        ]
    rep.table(["", "value"], rows)


def _blas(threads: dict) -> str:
    env = [f"{k}={v}" for k, v in threads.items() if k != "libraries"]
    libs = [f"{x.get('api')} {x.get('version')}: {x.get('threads')}" for x in threads.get("libraries", [])]
    return "; ".join(env + libs) or "-"


def _figures(rep: Report, directory: Path, figures: dict) -> None:
    if not figures:
        return
    rep.heading("Figures")
    for name, caption in figures.items():
        if (directory / name).is_file():
            rep.figure(directory / name, f"{name}: {caption}")


def _fmt(v, digits: int = 4) -> str:
    return "-" if v is None else (f"{v:.{digits}g}" if isinstance(v, float) else str(v))


def identify_report(path: Path, summary: dict, figures: dict, route: str, source: str) -> Path:
    """Write ``report.html`` of an identification from its ``summary`` (``summary.json``'s content,
    provenance included) and the figures written beside it (``{file name: caption}``)."""
    path = Path(path)
    lift, std = summary.get("lift_N"), summary.get("lift_std_N")
    band = "" if std is None else f" ± {std:.2g} N (1 sd)"
    rep = Report(f"wingopt identify: {summary.get('problem')} · {source} · {route}")
    rep.paragraph(f"Lift {_fmt(lift)} N{band}; status {summary.get('status')}.")
    _inputs(rep, summary.get("provenance", {}))
    est = summary.get("estimator", {})
    tension = est.get("tension", {}).get("source") if isinstance(est.get("tension"), dict) else None
    tension = tension or est.get("prestrain_source") or "-"
    field = summary.get("mean_field", {})
    rep.heading("Route and numbers")
    rows = [
        ("route", route),
        ("estimator", f"{summary.get('method')} ({summary.get('model')})"),
        ("tension from", tension),
        ("lift (N)", _fmt(lift)),
        ("lift 1-sigma (N)", _fmt(std)),
        ("load.csv integrates to (N)", _fmt(field.get("field_lift_N"))),
        ("load.csv is", field.get("what", "-")),
        ("band of load.csv", field.get("band", "-")),
        ("chi-square per datum", _fmt(summary.get("chi2_per_datum"))),
        ("model adequate", _fmt(summary.get("model_adequate"))),
        ("samples", _fmt(summary.get("samples"))),
        ("missing samples", _fmt(summary.get("missing_samples"))),
        ("mesh", "x".join(str(n) for n in summary.get("mesh", []))),
        ("wall time of the estimate (s)", _fmt(summary.get("wall_s"), 3)),
    ]
    for k in ("true_lift_N", "lift_error", "load_error"):
        if k in summary:
            rows.append((k, _fmt(summary[k])))
    if summary.get("parameters"):
        for k, v in summary["parameters"].items():
            sd = (summary.get("parameters_std") or {}).get(k)
            rows.append((k, f"{_fmt(v)} ± {_fmt(sd, 2)}"))
    rep.table(["", "value"], rows)
    rep.warnings([("identify", w) for w in summary.get("warnings", [])])
    _figures(rep, path.parent, figures)
    _provenance(rep, summary.get("provenance", {}), summary.get("problem_file"))
    return rep.write(path)


def calibration_report(path: Path, summary: dict, figures: dict) -> Path:
    """Write ``report.html`` of a calibration from its ``summary`` and its figures."""
    path = Path(path)
    rep = Report(f"wingopt calibrate: {summary.get('problem')} · {Path(str(summary.get('data'))).name}")
    rep.paragraph(
        f"Status {summary.get('status')}; chi-square per datum {_fmt(summary.get('chi2_per_datum'))} "
        f"({'adequate' if summary.get('model_adequate') else 'NOT adequate'})."
    )
    _inputs(rep, summary.get("provenance", {}))
    rep.heading("Identified parameters")
    std = summary.get("parameters_std", {})
    rows = [(k, _fmt(v), _fmt(std.get(k), 3)) for k, v in summary.get("parameters", {}).items()]
    rep.table(["parameter", "value", "1-sigma"], rows)
    corr = summary.get("correlation", {})
    if corr.get("names"):
        rep.table(
            ["", *corr["names"]],
            [(n, *[float(v) for v in row]) for n, row in zip(corr["names"], corr["matrix"])],
            "Posterior correlation",
        )
    rep.table(
        ["", "value"],
        [("samples", _fmt(summary.get("samples"))), ("wall time (s)", _fmt(summary.get("wall_s"), 3))],
    )
    rep.warnings([("calibrate", w) for w in summary.get("warnings", [])])
    _figures(rep, path.parent, figures)
    _provenance(rep, summary.get("provenance", {}), summary.get("problem_file"))
    return rep.write(path)
