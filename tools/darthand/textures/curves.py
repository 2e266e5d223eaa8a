"""Curves for overlays drawn as lines (creases, scars, veins): Bezier sampling and distance to a sampled curve."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def curve_distance(samples: np.ndarray, coords: np.ndarray, limit: float) -> tuple[np.ndarray, np.ndarray]:
    """Distance from points `coords` (M, d) to a densely sampled curve `samples` (S, d), capped at `limit`, and
    the curve parameter (index / (S - 1)) of the nearest sample."""
    d, i = cKDTree(samples).query(coords, distance_upper_bound=limit)
    far = ~np.isfinite(d)
    d[far], i[far] = limit, 0
    return d, i / max(len(samples) - 1, 1)


def bezier(points: np.ndarray, n: int = 200) -> np.ndarray:
    """`n` samples (n, d) of the Bezier curve with control points (K, d) (de Casteljau)."""
    pts = np.asarray(points, float)
    t = np.linspace(0.0, 1.0, n)[:, None, None]
    level = np.broadcast_to(pts, (n,) + pts.shape)
    while level.shape[1] > 1:
        level = (1 - t) * level[:, :-1] + t * level[:, 1:]
    return level[:, 0]
