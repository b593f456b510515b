"""The layout picture: designed sensors over the predicted load-error field (a Figure, nothing saved).

The field is the RMS over the nominal loads of the linearised, noise-free estimator's pointwise
error ``|P - f^|`` (:meth:`~wingopt.design.risk.BayesRisk.load_coefficients`), relative to the
RMS pressure: where the layout leaves the load unresolved. Built on
:class:`matplotlib.figure.Figure` (no pyplot state); the caller saves it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["predicted_error_field", "layout_figure"]


def predicted_error_field(result, nx: int = 57, ny: int = 29):
    """``(X, Y, E)``: the relative RMS pointwise error of the design's linearised estimates."""
    prob = result.problem
    sens = result.sensitivity
    loads = result.nominal_loads
    coefs = result.risk.load_coefficients(result.risk_layout)
    xs = np.linspace(0, prob.width, nx)
    ys = np.linspace(0, prob.height, ny)
    X, Y = np.meshgrid(xs, ys)
    err2 = np.zeros_like(X)
    ref2 = 0.0
    for P, c in zip(loads, coefs):
        est = sens.model.space.evaluate(c, X.ravel(), Y.ravel()).reshape(X.shape)
        truth = P(X, Y)
        err2 += (truth - est) ** 2
        ref2 += float(np.mean(truth**2))
    return X, Y, np.sqrt(err2 / len(loads)) / np.sqrt(ref2 / len(loads))


def layout_figure(result, default_rects=None, title: str | None = None):
    """Figure of the designed rectangles (and optionally the problem's own) over the error field."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    X, Y, E = predicted_error_field(result)
    prob = result.problem
    fig = Figure(figsize=(7.5, 4.2), layout="constrained")
    ax = fig.add_subplot()
    im = ax.pcolormesh(X * 1e3, Y * 1e3, E, shading="gouraud", cmap="magma_r", vmin=0)
    fig.colorbar(im, ax=ax, label="predicted |P - P^| / RMS P")
    if default_rects is not None:
        for r in default_rects:
            ax.add_patch(
                Rectangle(
                    (r[0] * 1e3, r[2] * 1e3),
                    (r[1] - r[0]) * 1e3,
                    (r[3] - r[2]) * 1e3,
                    fill=False,
                    ec="0.6",
                    ls="--",
                    lw=1.2,
                )
            )
    for i, r in enumerate(result.rects):
        ax.add_patch(
            Rectangle((r[0] * 1e3, r[2] * 1e3), (r[1] - r[0]) * 1e3, (r[3] - r[2]) * 1e3, fill=False, ec="c", lw=2)
        )
        ax.text((r[0] + r[1]) / 2 * 1e3, (r[2] + r[3]) / 2 * 1e3, f"S{i + 1}", color="c", ha="center", va="center")
    ax.set_xlim(0, prob.width * 1e3)
    ax.set_ylim(0, prob.height * 1e3)
    ax.set_aspect("equal")
    ax.set_xlabel("x (chord), mm")
    ax.set_ylabel("y (span), mm")
    value = result.predictions.get("risk_relative_load_error")
    ax.set_title(
        title or f"{result.count} sensors ({result.settings.criterion}); predicted mean load error {value:.3f}"
    )
    return fig
