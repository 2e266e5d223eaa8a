"""Where on an object a grasp is aimed: the object's centre by default, the middle of its part named "handle" where
it has one (a screwdriver's, a hammer's: `grip_target`), a mug's handle for the handle grasps.

A mug's handle is found from its mesh (the catalogue's mugs are one part: the handle is not named): the object's
axis is +z, the body a surface of revolution, the handle the vertices farther from the body's axis than its radius.
The body's radius is half the object's narrower horizontal extent; the handle lies at the end of the wider one
where the mesh is thinner across (a handle's width against the body's diameter). The aim is the handle's outer bar
(the handle's vertices within BAR of its outermost reach), approached from outside, the knuckle line along the bar,
held by HANDLE_CONTACTS.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

HANDLE_TYPES = ("medium_wrap",)     # closed through a handle (small_diameter's tighter curl puts a finger through
                                    # the mug's wall)
# A handle's bar is held between the palm and the index finger's middle phalanx, through the handle,
# the thumb on it, their pads resting on the mug's body (a pad held on the surface keeps its fingertip outside the
# thin wall: a free fingertip curls through it, where the skin's depth never shows).
HANDLE_HOLD = ("palm", "index_middle_palmar")
HANDLE_CONTACTS = HANDLE_HOLD + ("thumb_pad", "index_pad", "middle_pad")
MIN_HANDLE = 0.12   # the wider horizontal extent exceeds the narrower by this share: something sticks out
BAR = 0.012         # m: the handle's outer bar, measured in from its outermost reach
OUTSET = 0.008      # m: the contacts start this far out of the bar (the fingers round it, not the body)
BODY_MARGIN = 0.002  # m beyond the body's radius a vertex is the handle's


@dataclass(frozen=True)
class Aim:
    """Where a grasp closes: target (3,) object frame m, the point the contact parts' centre starts at; approach
    (3,) unit, from the object toward the hand; across (3,) unit, the knuckle line; contacts: the parts closed on
    it (None: the type's own)."""

    target: np.ndarray
    approach: np.ndarray
    across: np.ndarray
    contacts: tuple[str, ...] | None = None


def handle_aim(vertices: np.ndarray, category: str) -> Aim | None:
    """The handle's aim of a mug (vertices (N, 3) object frame, +z its axis), or None (no handle: a cup, not a
    mug)."""
    if category != "mug":
        return None
    v = np.asarray(vertices, np.float64)
    extent = np.ptp(v[:, :2], axis=0)
    wide = int(np.argmax(extent))
    if extent[wide] < (1 + MIN_HANDLE) * extent[1 - wide]:
        return None
    radius = extent[1 - wide] / 2
    side = handle_side(v, wide)
    centre = np.zeros(2)
    centre[1 - wide] = 0.5 * (v[:, 1 - wide].min() + v[:, 1 - wide].max())
    centre[wide] = (v[:, wide].min() + radius) if side > 0 else (v[:, wide].max() - radius)
    out = np.linalg.norm(v[:, :2] - centre, axis=1)
    handle = v[out > radius + BODY_MARGIN]
    if len(handle) == 0:
        return None
    bar = handle[np.linalg.norm(handle[:, :2] - centre, axis=1) > out.max() - BAR]
    outward = np.zeros(3)
    outward[wide] = side
    return Aim(bar.mean(0) + OUTSET * outward, outward, np.array([0.0, 0.0, 1.0]), HANDLE_CONTACTS)


def grip_target(item) -> np.ndarray:
    """(3,) object frame m: the middle (bounding box centre) of the item's part named "handle", else the origin
    (the object's centre). item: an ObjectItem (vertices, faces, face_part, parts); items without parts aim at
    their centre."""
    names = [p.get("name") for p in getattr(item, "parts", ())]
    if "handle" not in names or getattr(item, "face_part", None) is None:
        return np.zeros(3)
    faces = np.asarray(item.faces)[np.asarray(item.face_part) == names.index("handle")]
    v = np.asarray(item.vertices, np.float64)[np.unique(faces)]
    return 0.5 * (v.min(0) + v.max(0))


def handle_side(v: np.ndarray, wide: int) -> float:
    """+1 when the handle is at the + end of horizontal axis `wide`, else -1: the end whose outer slab is thinner
    across."""
    lo, hi = v[:, wide].min(), v[:, wide].max()
    slab = 0.1 * (hi - lo)
    across = [np.ptp(v[sel, 1 - wide]) for sel in (v[:, wide] < lo + slab, v[:, wide] > hi - slab)]
    return 1.0 if across[1] < across[0] else -1.0


def turned(axis: np.ndarray, approach: np.ndarray, degrees: float) -> np.ndarray:
    """(3,) the object's axis turned by `degrees` about the approach (the knuckle line of a type laid across the
    axis, as the index finger extension's handle lies diagonally in the palm)."""
    a = np.deg2rad(degrees)
    return np.cos(a) * axis + np.sin(a) * np.cross(approach, axis)
