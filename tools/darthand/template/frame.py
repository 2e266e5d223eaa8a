"""hm08's right hand -> MANO's canonical frame: metres, fingers toward -X, thumb toward +Z, palm facing -Y.

The rotation is read off the joints (not guessed from hm08's A-pose): X runs from the middle finger's MCP to the
wrist, Z from the little finger's MCP toward the index MCP (the thumb side) made orthogonal to X, and Y = Z x X,
which for a right hand is the back of the hand (so the palm faces -Y). The origin is put at the middle finger's MCP,
as in MANO's template (whose middle MCP sits within a few millimetres of the origin).
"""

from __future__ import annotations

import numpy as np

from darthand.errors import InputError

DECIMETRE = 0.1  # hm08's unit, in metres


def hand_frame(wrist: np.ndarray, middle_mcp: np.ndarray, index_mcp: np.ndarray,
               pinky_mcp: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation whose rows are the MANO axes X, Y, Z written in the source frame.

    A source point p maps to R @ (p - origin). All inputs (..., 3) in the source frame (batches broadcast).
    """
    x = _unit(wrist - middle_mcp)
    z = index_mcp - pinky_mcp
    z = _unit(z - np.sum(z * x, axis=-1, keepdims=True) * x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=-2)


def to_mano_frame(points: np.ndarray, rotation: np.ndarray, origin: np.ndarray, scale: float) -> np.ndarray:
    """(..., N, 3) source points -> (..., N, 3) points in MANO's frame: scale * R @ (p - origin); rotation
    (..., 3, 3), origin (..., 1, 3) or (3,) (batches broadcast)."""
    return scale * (points - origin) @ np.swapaxes(rotation, -1, -2)


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if (n < 1e-12).any():
        raise InputError("hm08 joint helpers: two joint centres coincide, cannot build the hand frame")
    return v / n
