"""The modal FvK model's prestrain model-form term, part of the realistic estimator's band."""

from __future__ import annotations

import numpy as np

__all__ = ["PRESTRAIN_MODEL_FORM_REL", "prestrain_std_with_model_form"]

PRESTRAIN_MODEL_FORM_REL = 0.03
"""Model-form 1-sigma of each identified prestrain, relative to it (added in quadrature).

Measured on Föppl–von Kármán truth (49x25, the seed protocol, docs/estimation_records.md): in the
bubble's first 20 ms this modal model is 0.6–0.8 % of the sensors' peak off the full FvK model,
and the prestrain split, the record's weakest direction, follows: e0x comes out 2–5 % low and e0y
2–3 % high, 1–2 of the data's own sigma, on every case measured (the first mode's combination and
the lift are not affected). The data's posterior cannot see a bias of its own model."""


def prestrain_std_with_model_form(name: str, estimate: float, std: float) -> float:
    """``std`` of parameter ``name`` with the modal FvK model's split term (prestrains only)."""
    if not name.startswith("prestrain"):
        return std
    return float(np.hypot(std, PRESTRAIN_MODEL_FORM_REL * abs(estimate)))
