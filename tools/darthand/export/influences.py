"""Skin influences as exported: the k strongest joints per vertex, renormalised (glTF engines read 4), and the
inverse (dense weights from per-vertex indices and weights).

Shapes: V vertices, J = 16 joints, k kept influences.
"""

from __future__ import annotations

import numpy as np

from darthand.errors import InputError
from darthand.model.hand_model import HandModel
from darthand.model.layout import NUM_JOINTS

INFLUENCE_CHOICES = ("4", "8", "all")  # the --influences values the CLI offers

def top_k_influences(weights: np.ndarray, k: int | None) -> tuple[np.ndarray, np.ndarray]:
    """The k strongest joints of every vertex: indices (V, k) int32 and weights (V, k) float64.

    Per vertex the weights are sorted descending (ties keep joint order), the rest dropped, and the kept ones
    renormalised to sum 1. Slots without influence (weight 0, also when k > J) get joint index 0, as glTF asks.
    k = None keeps all J joints.
    """
    w = np.asarray(weights, dtype=np.float64)
    V, J = w.shape
    k = J if k is None else int(k)
    if k < 1:
        raise InputError(f"influences: must be at least 1, got {k}")
    order = np.argsort(-w, axis=1, kind="stable")[:, :min(k, J)]
    kept = np.take_along_axis(w, order, axis=1)
    total = kept.sum(axis=1, keepdims=True)
    kept = np.divide(kept, total, out=np.zeros_like(kept), where=total > 0)
    idx = np.where(kept > 0, order, 0).astype(np.int32)
    if k > J:
        kept = np.concatenate([kept, np.zeros((V, k - J))], axis=1)
        idx = np.concatenate([idx, np.zeros((V, k - J), np.int32)], axis=1)
    return idx, kept


def influences_needed(weights: np.ndarray) -> int:
    """The most non-zero weights any vertex has (at least 1): storing that many influences loses nothing."""
    return max(1, int((np.asarray(weights) > 0).sum(axis=1).max(initial=0)))


def dense_weights(indices: np.ndarray, weights: np.ndarray, num_joints: int = NUM_JOINTS) -> np.ndarray:
    """(V, J) dense skin weights from per-vertex (indices, weights) (V, k): the inverse of `top_k_influences`."""
    V = indices.shape[0]
    dense = np.zeros((V, num_joints))
    np.add.at(dense, (np.repeat(np.arange(V), indices.shape[1]), indices.reshape(-1)), weights.reshape(-1))
    return dense


def pruned_model(model: HandModel, k: int | None) -> HandModel:
    """`model` with its skin weights pruned to k influences per vertex (what an exported asset skins with)."""
    if k is None or k >= model.weights.shape[1]:
        return model
    idx, w = top_k_influences(model.weights, k)
    return model.replace(weights=dense_weights(idx, w, model.weights.shape[1]))


def parse_influences(text: str | int | None) -> int | None:
    """'4' -> 4, '8' -> 8, 'all' / None -> None (every joint); anything else is an InputError."""
    if text is None or str(text) == "all":
        return None
    try:
        k = int(text)
    except ValueError:
        raise InputError(f"--influences: {text!r} is not a number or 'all'") from None
    if not 1 <= k <= NUM_JOINTS:
        raise InputError(f"--influences: {k} is outside 1..{NUM_JOINTS} (or 'all')")
    return k

