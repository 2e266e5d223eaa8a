"""Placing things on the hand's surface: named anatomical sites, tangent frames, decal and cylindrical
coordinates, random points by region, and neighbourhood queries over the baked texels.

Everything is defined in 3D on the rest-pose surface (never in UV space), so overlays stay continuous across
UV seams and look the same at every texture resolution.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from darthand.model.layout import FACE_LABEL_IDS, FINGER_JOINTS, FINGERS
from darthand.textures.bake import Bake
from darthand.model.regions import FOREARM_AXIS, PALM_NORMAL, face_geometry, skeleton_from_joints

_TREES: dict[str, cKDTree] = {}  # per process: one texel tree per bake
_BONE_ORDER: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # per process: texels grouped by bone


def texel_tree(bake: Bake) -> cKDTree:
    """A k-d tree over the bake's texel positions, built once per process and bake."""
    tree = _TREES.get(bake.key)
    if tree is None:
        _TREES.clear()
        tree = _TREES[bake.key] = cKDTree(bake.position, balanced_tree=False, compact_nodes=False)
    return tree


def _bone_order(bake: Bake) -> tuple[np.ndarray, np.ndarray]:
    """Texel indices sorted by bone, and each bone's start in that order (CSR style), once per process."""
    cached = _BONE_ORDER.get(bake.key)
    if cached is None:
        _BONE_ORDER.clear()
        bone = bake.fields["bone"].astype(np.int64)
        order = np.argsort(bone, kind="stable")
        starts = np.concatenate([[0], np.cumsum(np.bincount(bone[bone >= 0], minlength=21))])
        order = order[np.searchsorted(bone[order], 0):]  # drop unassigned (-1) texels
        cached = _BONE_ORDER[bake.key] = (order, starts)
    return cached


@dataclass(frozen=True)
class Frame:
    """A point on the surface with a tangent frame: `forward` (toward the fingertips where that makes sense),
    `side` = normal x forward, `normal` outward."""

    origin: np.ndarray
    forward: np.ndarray
    side: np.ndarray
    normal: np.ndarray


class Surface:
    """Placement queries over one bake (its texels and the mesh it came from)."""

    def __init__(self, bake: Bake):
        self.bake = bake
        m = bake.mesh
        self.vertices, self.faces = m["vertices"], m["faces"]
        self.face_labels = m["face_labels"]
        self.vertex_normals = m["vertex_normals"]
        self.joints, self.tips = m["joints"], m["tips"]
        self._face_geom: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @property
    def skeleton(self):
        """The bake's skeleton (rebuilt from its joints and tips)."""
        return skeleton_from_joints(self.joints, self.tips)

    # ------------------------------------------------------------------ texel queries
    @property
    def tree(self) -> cKDTree:
        return texel_tree(self.bake)

    def ball(self, centre, radius: float) -> np.ndarray:
        """Sorted indices of texels within `radius` metres of `centre` (3,)."""
        return np.sort(np.asarray(self.tree.query_ball_point(np.asarray(centre, float), radius), np.int64))

    def balls(self, centres: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
        """Texels within `radius` of any of `centres` (K, 3): (texel index (M,), centre index (M,)) pairs."""
        if len(centres) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        hits = self.tree.query_ball_point(np.asarray(centres, float), radius)
        counts = np.array([len(h) for h in hits])
        idx = np.concatenate([np.asarray(h, np.int64) for h in hits]) if counts.sum() else np.zeros(0, np.int64)
        return idx, np.repeat(np.arange(len(centres)), counts)

    @property
    def texel_size(self) -> float:
        """Mean edge length of a texel on the surface, metres (surface area / covered texels, square-rooted)."""
        area = face_geometry(self.vertices, self.faces)[2].sum()
        return float(np.sqrt(area / max(int(self.bake.inside.sum()), 1)))

    # ------------------------------------------------------------------ anatomy
    def joint(self, finger: str, level: int) -> np.ndarray:
        return self.joints[FINGER_JOINTS[finger][level]]

    def tip(self, finger: str) -> np.ndarray:
        return self.tips[FINGERS.index(finger)]

    def chain(self, finger: str) -> list[np.ndarray]:
        """Joint positions root -> tip of a finger (4 points)."""
        return [self.joints[j] for j in FINGER_JOINTS[finger]] + [self.tip(finger)]

    def surface_point(self, inner: np.ndarray, direction: np.ndarray,
                      reach: float = 0.06) -> tuple[np.ndarray, np.ndarray]:
        """Where the ray from `inner` along `direction` leaves the skin, approximately: the mesh vertex closest to
        the ray (within `reach`), moved onto the ray. Returns the point and the vertex normal there."""
        d = np.asarray(direction, float)
        d = d / np.linalg.norm(d)
        rel = self.vertices - inner
        along = rel @ d
        off = np.linalg.norm(rel - np.outer(along, d), axis=1)
        best = int(np.argmin(np.where((along > 0) & (along < reach), off + 0.05 * np.abs(along), np.inf)))
        return inner + along[best] * d, self.vertex_normals[best]

    def frame_at(self, point: np.ndarray, normal: np.ndarray, forward: np.ndarray) -> Frame:
        """A tangent frame at `point` whose forward axis is `forward` projected onto the tangent plane."""
        n = np.asarray(normal, float) / np.linalg.norm(normal)
        f = np.asarray(forward, float) - np.dot(forward, n) * n
        if np.linalg.norm(f) < 1e-9:
            f = np.cross(n, [0.0, 0.0, 1.0])
        f /= np.linalg.norm(f)
        return Frame(np.asarray(point, float), f, np.cross(n, f), n)

    def site(self, name: str, along: float = 0.5, across: float = 0.0, finger: str = "middle",
             level: int = 0) -> Frame:
        """A named placement site, positioned by `along` / `across` in [0, 1] / [-1, 1] where meaningful.

        dorsum        back of the hand between the wrist and the knuckles (`across` -1 thumb side .. 1 pinky)
        palm          palm centre region, same parameters
        wrist_dorsal  back of the wrist / forearm (`along` 0 at the wrist joint .. 1 at the forearm end)
        wrist_inner   inner (palmar) wrist / forearm
        finger        back of `finger`'s segment `level`, `along` its length
        thumb_web     back of the web between thumb and index
        hand_edge     the little-finger edge of the palm
        """
        fingers_dir = -FOREARM_AXIS
        wrist = self.joints[0]
        if name in ("dorsum", "palm"):
            near, far = self.joint("index", 0), self.joint("pinky", 0)
            centre_root = 0.5 * (near + far)
            half = 0.5 * (far - near)
            inner = wrist + along * (centre_root - wrist) + 0.75 * across * half * min(1.0, 0.4 + along)
            up = -PALM_NORMAL if name == "dorsum" else PALM_NORMAL
            p, n = self.surface_point(inner, up)
            return self.frame_at(p, n, fingers_dir)
        if name in ("wrist_dorsal", "wrist_inner"):
            extent = self._forearm_extent()
            inner = wrist + FOREARM_AXIS * (0.004 + along * max(extent - 0.012, 0.0))
            inner = inner + np.array([0.0, 0.0, 0.004 * across])
            up = -PALM_NORMAL if name == "wrist_dorsal" else PALM_NORMAL
            p, n = self.surface_point(inner, up)
            return self.frame_at(p, n, fingers_dir)
        if name == "finger":
            chain = self.chain(finger)
            a, b = chain[level], chain[level + 1]
            inner = a + along * (b - a)
            axis = (b - a) / np.linalg.norm(b - a)
            up = -PALM_NORMAL - np.dot(-PALM_NORMAL, axis) * axis
            p, n = self.surface_point(inner, up)
            return self.frame_at(p, n, axis)
        if name == "thumb_web":
            inner = 0.5 * (self.joint("thumb", 1) + self.joint("index", 0))
            inner = inner + along * 0.3 * (wrist - inner)
            p, n = self.surface_point(inner, -PALM_NORMAL)
            return self.frame_at(p, n, self.joint("index", 0) - self.joint("thumb", 1))
        if name == "hand_edge":
            far = self.joint("pinky", 0)
            inner = wrist + (0.3 + 0.5 * along) * (far - wrist)
            side = np.array([0.0, 0.0, -1.0])
            p, n = self.surface_point(inner, side)
            return self.frame_at(p, n, fingers_dir)
        raise ValueError(f"unknown site {name!r}")

    def _forearm_extent(self) -> float:
        return float(max(self.vertices[:, 0].max() - self.joints[0, 0], 0.01))

    # ------------------------------------------------------------------ coordinates of texels
    def decal(self, frame: Frame, radius: float, facing: float = 0.2,
              depth: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Texels of a planar decal at `frame`: within `radius` of its origin, with normals within
        acos(`facing`) of its normal and within `depth` (default radius / 2) of its plane.

        Returns texel indices (M,) and their decal coordinates (M, 2) in metres: (forward, side).
        """
        idx = self.ball(frame.origin, radius)
        rel = self.bake.position[idx].astype(np.float64) - frame.origin
        ok = (self.bake.normal[idx] @ frame.normal >= facing) & (np.abs(rel @ frame.normal) <= (depth or radius / 2))
        idx, rel = idx[ok], rel[ok]
        return idx, np.stack([rel @ frame.forward, rel @ frame.side], 1)

    def cylinder(self, start: np.ndarray, end: np.ndarray, dorsal: np.ndarray, texels: np.ndarray):
        """Cylindrical coordinates of `texels` around the axis start -> end: axial distance from start (M,),
        angle from the `dorsal` direction (M,) in (-pi, pi], distance from the axis (M,); metres and radians."""
        axis = (end - start) / np.linalg.norm(end - start)
        up = dorsal - np.dot(dorsal, axis) * axis
        up /= np.linalg.norm(up)
        side = np.cross(axis, up)
        rel = self.bake.position[texels].astype(np.float64) - start
        a = rel @ axis
        radial = rel - np.outer(a, axis)
        return a, np.arctan2(radial @ side, radial @ up), np.linalg.norm(radial, axis=1)

    def texels_of_bones(self, bones) -> np.ndarray:
        """Sorted indices of texels whose face belongs to one of `bones` (Skeleton bone indices)."""
        order, starts = _bone_order(self.bake)
        parts = [order[starts[b]:starts[b + 1]] for b in np.atleast_1d(bones) if 0 <= b < len(starts) - 1]
        return np.sort(np.concatenate(parts)) if parts else np.zeros(0, np.int64)

    # ------------------------------------------------------------------ random points on the mesh
    def sample_points(self, rng: np.random.Generator, n: int, label_weights: dict[str, float],
                      where=None) -> tuple[np.ndarray, np.ndarray]:
        """`n` points uniformly distributed over the surface area, faces weighted by their label's weight (and by
        `where(centroids, normals) -> (F,) weights` if given). Returns points (n, 3) and unit normals (n, 3)."""
        if self._face_geom is None:
            self._face_geom = face_geometry(self.vertices, self.faces)
        centroid, fnormal, area = self._face_geom
        w = np.zeros(len(self.faces))
        for label, weight in label_weights.items():
            w[self.face_labels == FACE_LABEL_IDS[label]] = weight
        w *= area
        if where is not None:
            w *= where(centroid, fnormal)
        if n == 0 or w.sum() <= 0:
            return np.zeros((0, 3)), np.zeros((0, 3))
        f = rng.choice(len(w), size=n, p=w / w.sum())
        r1, r2 = rng.random(n), rng.random(n)
        s = np.sqrt(r1)
        bary = np.stack([1 - s, s * (1 - r2), s * r2], 1)
        corners = self.faces[f]
        points = np.einsum("nk,nki->ni", bary, self.vertices[corners])
        normals = np.einsum("nk,nki->ni", bary, self.vertex_normals[corners])
        return points, normals / np.linalg.norm(normals, axis=1, keepdims=True)
