"""Shapes of a model: checked betas and the rest surface they give.

MANO's shape blend: v_shaped = v_template + shapedirs . beta, joints J = J_regressor . v_shaped (so the skeleton
follows the surface). `HandModel.shaped` bakes one shape into a model that every stage can take as it takes any
other (fit accessories, bake textures, export, render): its template is the shaped surface, its joints regress
from it as before, and its shape directions stay, so betas given to it later add to the baked ones. This module
reads a model's fields only, so it needs `HandModel` for its annotations alone (hand_model imports it).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from darthand.errors import InputError

if TYPE_CHECKING:
    from darthand.model.hand_model import HandModel


def check_betas(model: HandModel, betas) -> np.ndarray:
    """betas as a float64 array (..., S), S <= model.num_betas, finite; one-line errors otherwise."""
    b = np.asarray(betas, dtype=np.float64)
    if b.ndim == 0 or b.shape[-1] > model.num_betas:
        raise InputError(f"betas: {b.shape[-1] if b.ndim else 1} given but the model has {model.num_betas} shape "
                         "directions")
    if not np.isfinite(b).all():
        raise InputError(f"betas: non-finite value at index {tuple(int(i) for i in np.argwhere(~np.isfinite(b))[0])}")
    return b


def shaped_vertices(model: HandModel, betas) -> np.ndarray:
    """(..., V, 3) rest surface of betas (..., S) (missing trailing betas are zero)."""
    b = check_betas(model, betas)
    return model.v_template + np.einsum("vcs,...s->...vc", model.shapedirs[:, :, :b.shape[-1]], b)

