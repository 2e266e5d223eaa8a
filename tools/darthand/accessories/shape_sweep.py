"""Penetration of the accessories over hand shapes: the catalogue refitted to sampled shapes (reshape.py), each
shape posed in the named gestures, measured as the stage measures the built hand (collide.py: the overlap depth
both ways, hand vertices inside the item and item vertices inside the capped hand).

Per rigid item, shape and gesture two figures (metres): `fit`, against the part of the hand it is fitted to (a
ring's finger: the vertices its finger's joints dominate; a wrist item's: the wrist joint's), and `depth`, against
the whole hand (a neighbouring finger folded onto a ring counts there). The same without refitting (the items as
fitted to the built hand, worn by the shaped hand) shows what the refit buys. Gloves follow the hand's shape
directions exactly (their vertices carry them: reshape.py) and are not swept here.

Shapes: N shapes, G gestures, A rigid accessories, S shape directions.
"""

from __future__ import annotations

import time

import numpy as np

from darthand.accessories.collide import ClosedHand, Solid
from darthand.accessories.fit import RING_JOINTS
from darthand.accessories.loader import Accessory
from darthand.accessories.reshape import ShapeRefitter
from darthand.model.forward import forward
from darthand.model.hand_model import HandModel
from darthand.model.layout import FINGER_JOINTS

SHAPE_STREAM = 15


def sample_shapes(model: HandModel, n: int, seed: int = 0, limit: float = 3.0) -> np.ndarray:
    """(n, S) betas ~ N(0, I) clipped at +-limit, from their own stream; the first row 0 (the built hand)."""
    b = np.clip(np.random.default_rng([seed, SHAPE_STREAM]).standard_normal((n, model.num_betas)), -limit, limit)
    b[0] = 0
    return b


def own_vertices(model: HandModel, acc: Accessory) -> np.ndarray:
    """(V,) bool: the hand vertices of the part an item is fitted to (its finger's, or the wrist joint's)."""
    dominant = np.argmax(model.weights, axis=1)
    if acc.parent_joint == 0:
        return dominant == 0
    finger = next(f for f, j in RING_JOINTS.items() if j == acc.parent_joint)
    return np.isin(dominant, FINGER_JOINTS[finger])


def penetration_over_shapes(model: HandModel, accessories: list[Accessory], betas: np.ndarray, poses: np.ndarray,
                            refit: bool = True, refitter: ShapeRefitter | None = None,
                            progress=None) -> dict:
    """{'ids' (A,), 'fit' (A, N, G), 'depth' (A, N, G) metres, 'refit_seconds' (N,)} of the rigid items over
    shapes betas (N, S) and poses (G, 48). progress: called with (shape index, N) after each shape."""
    rigid = [a for a in accessories if not a.skinned and a.rest_transform is not None]
    refitter = refitter or ShapeRefitter(model, rigid).prepare()
    hand = ClosedHand(model.faces)
    own = [own_vertices(model, a) for a in rigid]
    A, N, G = len(rigid), len(betas), len(poses)
    fit, depth = np.zeros((A, N, G)), np.zeros((A, N, G))
    seconds = np.zeros(N)
    for n, b in enumerate(betas):
        t = time.perf_counter()
        items = refitter.refit(b, [a.id for a in rigid]) if refit else rigid
        seconds[n] = time.perf_counter() - t
        posed = forward(model, poses, np.tile(b, (G, 1)))
        hands = [hand.solid(v) for v in posed.vertices]
        for i, acc in enumerate(items):
            solid = Solid(acc.vertices, acc.faces)                          # its rest frame: static there
            G_j = posed.transforms[:, acc.parent_joint]                     # (G, 4, 4)
            inv = np.linalg.inv(G_j)
            for g in range(G):
                in_frame = posed.vertices[g] @ inv[g, :3, :3].T + inv[g, :3, 3]   # the hand moved into it
                worn = acc.vertices @ G_j[g, :3, :3].T + G_j[g, :3, 3]
                fit[i, n, g] = solid.max_depth(in_frame[own[i]])
                depth[i, n, g] = max(solid.max_depth(in_frame), hands[g].max_depth(worn))
        if progress is not None:
            progress(n, N)
    return {"ids": [a.id for a in rigid], "fit": fit, "depth": depth, "refit_seconds": seconds}


def summary(result: dict, names: list[str]) -> dict:
    """Per item and overall: the worst and 99th-percentile penetrations (mm) over shapes and gestures, the worst
    (shape index, gesture) of each."""
    fit, depth = result["fit"] * 1000, result["depth"] * 1000
    items = {}
    for i, acc_id in enumerate(result["ids"]):
        n, g = np.unravel_index(int(np.argmax(fit[i])), fit[i].shape)
        items[acc_id] = {"fit_max_mm": round(float(fit[i].max()), 4),
                         "fit_p99_mm": round(float(np.percentile(fit[i], 99)), 4),
                         "depth_max_mm": round(float(depth[i].max()), 4),
                         "worst": {"shape": int(n), "gesture": names[g]} if fit[i].max() > 0 else None}
    return {"items": items,
            "fit_max_mm": round(float(fit.max()), 4) if fit.size else 0.0,
            "fit_p99_mm": round(float(np.percentile(fit, 99)), 4) if fit.size else 0.0,
            "depth_max_mm": round(float(depth.max()), 4) if depth.size else 0.0,
            "share_over_1mm": round(float((fit > 1.0).mean()), 5) if fit.size else 0.0,
            "by_gesture_fit_max_mm": {name: round(float(fit[:, :, g].max()), 4) for g, name in enumerate(names)},
            "by_shape_fit_max_mm": [round(float(x), 4) for x in fit.max(axis=(0, 2))]}
