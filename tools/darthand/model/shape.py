"""Shapes of a model: the rest surface of given betas, and the model of one shape.

MANO's shape blend: v_shaped = v_template + shapedirs . beta, joints J = J_regressor . v_shaped (so the skeleton
follows the surface). `shaped_model` bakes one shape into a model that every stage can take as it takes any
other (fit accessories, bake textures, export, render): its template is the shaped surface, its joints regress
from it as before, and its shape directions stay, so betas given to it later add to the baked ones.
"""

from __future__ import annotations

import numpy as np

from darthand.errors import InputError
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


def shaped_model(model: HandModel, betas) -> HandModel:
    """The model of one shape, betas (S,): template = `shaped_vertices`, everything else kept; the betas are
    recorded in meta['betas'] (added to any already baked in)."""
    b = check_betas(model, betas)
    if b.ndim != 1:
        raise InputError(f"betas: one shape expected, got shape {b.shape}")
    baked = np.zeros(model.num_betas)
    baked[:len(b)] = b
    previous = np.asarray(model.meta.get("betas", np.zeros(model.num_betas)), dtype=np.float64)
    if previous.shape == baked.shape:
        baked = baked + previous
    return model.replace(v_template=shaped_vertices(model, b), meta={**model.meta, "betas": baked.tolist()})
