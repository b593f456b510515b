"""Figures of a morphing run (the seed's Figs. 5.18–5.38), optionally against a second run.

``plot_morph(out, result, compare_with)`` writes ``voltages.png`` (voltage histories),
``tip_corners.png`` (tip-corner histories against the target), ``shape_error.png``,
``surface.png`` (final surface against the target), ``strains.png`` (final surface strain fields
on the top face of the substrate) and ``snapshots.png`` (edge deflection at a few instants).
With ``compare_with`` (e.g. the QP against LQR saturated at the same limits) the histories are
overlaid and the surfaces shown side by side on one colour scale.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wingopt.errors import InputError
from wingopt.plots import pyplot as _pyplot
from wingopt.plots import save as _save

__all__ = [
    "FIGURES",
    "figure_names",
    "plot_morph",
    "plot_voltages",
    "plot_tip_corners",
    "plot_shape_error",
    "plot_surface",
    "plot_strains",
    "plot_robustness",
]

GRID = (31, 121)
"""Evaluation grid (x, y) of the surface and strain figures."""


def _label(result) -> str:
    lim = ""
    if result.vmin is not None or result.vmax is not None:
        lo = "-inf" if result.vmin is None else f"{result.vmin:g}"
        hi = "+inf" if result.vmax is None else f"{result.vmax:g}"
        lim = f" [{lo}, {hi}] V"
    return f"{result.method}{lim}"


def plot_voltages(path: Path | None, results: list):
    """Voltage history of every patch (one panel per run, shared voltage axis), limits dashed."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(results), figsize=(6.2 * len(results), 3.8), sharey=True, squeeze=False)
    for ax, res in zip(axes[0], results):
        cl = res.closed_loop
        t = np.append(cl.t_u, cl.t_u[-1] + cl.period)
        for j, name in enumerate(res.model.patch_names):
            ax.step(t, np.append(cl.u[:, j], cl.u[-1, j]) / 1e3, where="post", lw=1.2, label=name, color=f"C{j}")
        for v in (res.vmin, res.vmax):
            if v is not None:
                ax.axhline(v / 1e3, color="k", ls="--", lw=0.8)
        ax.set_xlabel("t (s)")
        ax.set_title(f"{res.shape}: voltages, {_label(res)}")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("voltage (kV)")
    axes[0][-1].legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=8)
    return _save(fig, path)


def _axes(ax, figsize):
    if ax is not None:
        return ax.figure, ax, False
    fig, ax = _pyplot().subplots(figsize=figsize)
    return fig, ax, True


def plot_tip_corners(path: Path | None, results: list, ax=None):
    """Tip corners ``w(0, 0)`` and ``w(W, 0)`` over time; targets dashed. Returns the figure;
    ``ax``: draw into this axes instead (nothing written)."""
    fig, ax, own = _axes(ax, (6.4, 3.8))
    styles = ["-", "--", ":"]
    for i, res in enumerate(results):
        cl = res.closed_loop
        ax.plot(cl.t, cl.tip[:, 0] * 100, color="C0", ls=styles[i % 3], label=f"w(0, 0), {_label(res)}")
        ax.plot(cl.t, cl.tip[:, 1] * 100, color="C3", ls=styles[i % 3], label=f"w(W, 0), {_label(res)}")
    tgt = results[0].model.tip_corners(results[0].target) * 100
    for v, c in zip(tgt, ("C0", "C3")):
        ax.axhline(v, color=c, lw=0.8, alpha=0.6, ls="-.")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("tip deflection (cm)")
    ax.set_title(f"{results[0].shape}: tip corners (dash-dot: target)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    return _save(fig, path if own else None, margins=True)


def plot_shape_error(path: Path | None, results: list, ax=None):
    """``||z - z_d||_M / ||z_d||_M`` over time; returns the figure (``ax`` as in :func:`plot_tip_corners`)."""
    fig, ax, own = _axes(ax, (6.4, 3.4))
    for res in results:
        cl = res.closed_loop
        ax.plot(cl.t, cl.shape_error, label=f"{_label(res)}: final {cl.final_shape_error:.3f}")
    for k, v in results[0].extras.items():
        if k == "static_optimum_error" and v is not None:
            ax.axhline(v, color="k", ls=":", lw=1, label=f"static optimum {v:.3f}")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("relative shape error (M-norm)")
    ax.set_ylim(bottom=0)
    ax.set_title(f"{results[0].shape}: shape error")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path if own else None, margins=True)


def plot_surface(path: Path | None, results: list):
    """Final surface of each run beside the target (mm, one colour scale) and a 3-D view."""
    plt = _pyplot()
    model = results[0].model
    X, Y, Wt = model.evaluate_grid(results[0].target, *GRID)
    fields = [("target", Wt)] + [(_label(r), model.evaluate_grid(r.closed_loop.z[-1], *GRID)[2]) for r in results]
    lim = max(float(np.abs(f).max()) for _, f in fields) * 1e3 or 1.0
    fig = plt.figure(figsize=(2.6 * len(fields) + 4.6, 5.0))
    for i, (name, F) in enumerate(fields):
        ax = fig.add_subplot(1, len(fields) + 1, i + 1)
        im = ax.pcolormesh(X * 1e3, Y * 1e3, F * 1e3, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="gouraud")
        ax.set_aspect("equal")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("x (mm)")
        if i == 0:
            ax.set_ylabel("y (mm), root at top")
        else:
            ax.set_yticklabels([])
    fig.colorbar(im, ax=fig.axes, label="w (mm)", shrink=0.8, location="left")
    ax3 = fig.add_subplot(1, len(fields) + 1, len(fields) + 1, projection="3d")
    ax3.plot_surface(X * 1e3, Y * 1e3, fields[1][1] * 1e3, cmap="viridis", alpha=0.85, linewidth=0)
    ax3.plot_wireframe(X * 1e3, Y * 1e3, Wt * 1e3, color="k", lw=0.4, rstride=10, cstride=6)
    ax3.set_xlabel("x (mm)")
    ax3.set_ylabel("y (mm)")
    ax3.set_zlabel("w (mm)")
    ax3.set_title(f"final ({fields[1][0]}), target wireframe", fontsize=9)
    fig.suptitle(f"{results[0].shape}: final surface")
    return _save(fig, path, tight=False)  # tight_layout cannot place the 3-D axes and left colour bar


def plot_strains(path: Path | None, result):
    """Final ``eps_xx``, ``eps_yy``, ``gamma_xy`` on the top face of the substrate (Figs. 5.22–5.24)."""
    plt = _pyplot()
    model = result.model
    xs = np.linspace(0, model.problem.width, GRID[0])
    ys = np.linspace(0, model.problem.length, GRID[1])
    X, Y = np.meshgrid(xs, ys)
    E = model.surface_strains(result.closed_loop.z[-1], X.ravel(), Y.ravel())
    fig, axes = plt.subplots(1, 3, figsize=(10.5, 5.2))
    for ax, comp, name in zip(axes, E, ("eps_xx", "eps_yy", "gamma_xy")):
        F = comp.reshape(X.shape) * 1e6
        lim = float(np.abs(F).max()) or 1.0
        im = ax.pcolormesh(X * 1e3, Y * 1e3, F, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="gouraud")
        ax.set_aspect("equal")
        ax.set_title(f"{name} (microstrain)", fontsize=9)
        ax.set_xlabel("x (mm)")
        fig.colorbar(im, ax=ax, shrink=0.7)
    axes[0].set_ylabel("y (mm)")
    fig.suptitle(f"{result.shape}: final surface strains, {_label(result)}")
    return _save(fig, path)


def plot_snapshots(path: Path | None, result, times=(0.1, 0.25, 0.5, 1.0, 2.0)):
    """Deflection along both edges (x = 0 and x = W) at a few instants (cf. Fig. 5.21)."""
    plt = _pyplot()
    model = result.model
    cl = result.closed_loop
    ys = np.linspace(0, model.problem.length, 121)
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.6), sharey=True)
    for ax, x, name in zip(axes, (0.0, model.problem.width), ("leading edge x = 0", "trailing edge x = W")):
        for i, t in enumerate([t for t in times if t <= cl.t[-1] + 1e-12]):
            k = int(np.argmin(np.abs(cl.t - t)))
            ax.plot(
                ys * 1e3,
                model.evaluate(cl.z[k], np.full_like(ys, x), ys) * 1e3,
                color=f"C{i}",
                label=f"t = {cl.t[k]:g} s",
            )
        ax.plot(ys * 1e3, model.evaluate(result.target, np.full_like(ys, x), ys) * 1e3, "k--", lw=1, label="target")
        ax.set_xlabel("y (mm), tip at 0, root at 600")
        ax.set_title(name, fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("w (mm)")
    axes[1].legend(fontsize=8)
    fig.suptitle(f"{result.shape}: deflection snapshots, {_label(result)}")
    return _save(fig, path)


FIGURES = ("voltages", "tip_corners", "shape_error", "surface", "strains", "snapshots")
"""The figures :func:`plot_morph` writes (``NAME.png``), in order."""


def figure_names(figures=None) -> tuple[str, ...]:
    """The names of :data:`FIGURES` that ``figures`` selects (``None``: all), checked."""
    if figures is None:
        return FIGURES
    if isinstance(figures, str) or not all(isinstance(n, str) for n in figures):
        raise InputError(f"figures = {figures!r}: expected names from {', '.join(FIGURES)}")
    unknown = [n for n in figures if n not in FIGURES]
    if unknown:
        raise InputError(f"figures = {figures!r}: unknown {', '.join(unknown)}; expected some of {', '.join(FIGURES)}")
    return tuple(n for n in FIGURES if n in figures)


def plot_morph(out: Path, result, compare_with=None, figures=None) -> list[Path]:
    """Figures of a run into the directory ``out``; returns their paths.

    ``figures``: names from :data:`FIGURES` to write (default all of them).
    """
    out = Path(out)
    names = figure_names(figures)
    runs = [result] + ([compare_with] if compare_with is not None else [])
    draw = {
        "voltages": lambda path: plot_voltages(path, runs),
        "tip_corners": lambda path: plot_tip_corners(path, runs),
        "shape_error": lambda path: plot_shape_error(path, runs),
        "surface": lambda path: plot_surface(path, runs),
        "strains": lambda path: plot_strains(path, result),
        "snapshots": lambda path: plot_snapshots(path, result),
    }
    for name in names:
        draw[name](out / f"{name}.png")
    return [out / f"{n}.png" for n in names]


def plot_functional_gains(path: Path | None, profiles: dict):
    """Bending and velocity gains of PZ1/PZ4/PZ7 along ``x = W/2`` for several meshes (Figs. 5.12–5.17).

    ``profiles``: mesh label -> :func:`~wingopt.control.riccati_large.gain_profiles` output; meshes
    in progressively darker grey, as in the seed.
    """
    plt = _pyplot()
    labels = list(profiles)
    first = profiles[labels[0]]
    npatch = len(first["patches"])
    fig, axes = plt.subplots(2, npatch, figsize=(4.2 * npatch, 6.4), sharex=True, squeeze=False)
    greys = np.linspace(0.7, 0.0, len(labels))
    for j in range(npatch):
        for lab, g in zip(labels, greys):
            pr = profiles[lab]
            axes[0][j].plot(pr["y"], pr["bending"][j], color=str(g), lw=1.4, label=lab)
            axes[1][j].plot(pr["y"], pr["velocity"][j], color=str(g), lw=1.4, label=lab)
        axes[0][j].set_title(f"bending gain, {first['patches'][j]}", fontsize=10)
        axes[1][j].set_title(f"velocity gain, {first['patches'][j]}", fontsize=10)
        axes[1][j].set_xlabel("spanwise position y (m), x = W/2")
        for a in (axes[0][j], axes[1][j]):
            a.grid(alpha=0.3)
    axes[0][0].set_ylabel("d^2 k_b / dy^2")
    axes[1][0].set_ylabel("k_v")
    axes[0][-1].legend(fontsize=8)
    return _save(fig, path)


def plot_robustness(records: list[dict], path: Path | None, metric: str = "settled_relative_excess"):
    """The excess shape error over each plant's best, per shape, one column of dots per controller.

    ``records``: :func:`wingopt.workflows.morph_robustness.plant_record` records (one per plant);
    ``metric``: ``"relative_excess"`` (final shape) or ``"settled_relative_excess"`` (the mean
    shape of the last 0.25 s). A dashed line marks the 2 % of issue 34.
    """
    recs = [r for r in records if "results" in r]
    if not recs:
        raise InputError("plot_robustness: no records with results")
    shapes = list(recs[0]["results"])
    ctrls = list(recs[0]["results"][shapes[0]])
    fig, axes = _pyplot().subplots(1, len(shapes), figsize=(3.4 * len(shapes), 3.4), sharey=True)
    axes = np.atleast_1d(axes)
    rng = np.random.default_rng(0)  # horizontal jitter only
    for ax, shape in zip(axes, shapes):
        for j, c in enumerate(ctrls):
            v = 100.0 * np.array([r["results"][shape][c][metric] for r in recs])
            ax.scatter(j + 0.12 * rng.standard_normal(v.size), v, s=9, alpha=0.7)
            ax.plot([j - 0.3, j + 0.3], [np.median(v)] * 2, color="k", lw=1.5)
        ax.axhline(2.0, color="0.4", ls="--", lw=0.8)
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.set_xticks(range(len(ctrls)), ctrls)
        ax.set_yscale("symlog", linthresh=2.0)
        ax.set_title(f"{shape} ({len(recs)} plants)")
    axes[0].set_ylabel("excess over the plant's best, %")
    return _save(fig, path)
