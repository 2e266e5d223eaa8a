"""The ray-tracing scene: one Embree triangle mesh per posed surface (geomID = its index in the subject).

embreex builds static scenes only (no vertex-buffer updates, no instancing), so a pose change means a new scene;
what did not move is not recomputed on the numpy side (see assets.HandAssets), and a scene whose surfaces are the
same arrays is reused (only the camera or the lights changed). Building the hand (3.5k triangles) and a ring (6.4k)
costs a few milliseconds (benchmarks/render.py reports it).

The scene is committed on construction (a one-ray query) so that the parallel queries of trace.py start from a
committed scene.
"""

from __future__ import annotations

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh
from embreex.rtcore import EmbreeDevice

from darthand.render.subject import Subject, Surface

_DEVICE = None


def device() -> EmbreeDevice:
    """One Embree device for the process (creating one per scene costs more than building the hand)."""
    global _DEVICE
    if _DEVICE is None:
        _DEVICE = EmbreeDevice()
    return _DEVICE


class FaceData:
    """Per-face shading data of one posed surface, laid out for one gather per batch of hits: `table` (K, F)
    float32, its rows (component-major, so that the gathered (K, M) rows are contiguous vectors):

        0..8    corner positions, corner k coordinate c at row 3k + c
        9..17   corner vertex normals, likewise
        18..20  unit geometric normal
        21..26  corner uvs, corner k (u, v) at rows 21 + 2k, 22 + 2k          (with UVs)
        27      uv scale sqrt(uv area / surface area): uv units per metre on the face   (with UVs)
    """

    POSITION, NORMAL, GEOMETRIC, UV, UV_SCALE = 0, 9, 18, 21, 27

    def __init__(self, surface: Surface):
        f = surface.faces
        corners = surface.vertices[f]                                            # (F, 3, 3) float32
        n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        area2 = np.linalg.norm(n, axis=1)
        rows = [corners.reshape(-1, 9), surface.normals[f].reshape(-1, 9),
                n / np.maximum(area2, 1e-30)[:, None]]
        self.has_uvs = surface.uvs is not None
        if self.has_uvs:
            cuv = surface.uvs[surface.faces_uv]                                  # (F, 3, 2)
            d1, d2 = cuv[:, 1] - cuv[:, 0], cuv[:, 2] - cuv[:, 0]
            uv_area2 = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
            scale = np.sqrt(uv_area2 / np.maximum(area2, 1e-30))
            rows += [cuv.reshape(-1, 6), scale[:, None]]
        self.table = np.ascontiguousarray(np.concatenate(rows, axis=1, dtype=np.float32).T)

    def gather(self, prim: np.ndarray) -> np.ndarray:
        """(K, M) float32 rows of the faces `prim` (M,)."""
        return np.take(self.table, prim, axis=1)


class Scene:
    """The Embree scene of a subject's surfaces, committed, with the scene's size for ray offsets and the per-face
    shading data of each surface."""

    def __init__(self, subject: Subject):
        self.subject = subject
        self.surfaces = subject.surfaces
        self.faces = [FaceData(s) for s in self.surfaces]
        self.embree = rtcore_scene.EmbreeScene(device())
        for s in self.surfaces:
            TriangleMesh(self.embree, np.ascontiguousarray(s.vertices, np.float32),
                         np.ascontiguousarray(s.faces, np.int32))
        pts = subject.all_vertices()
        self.lo, self.hi = pts.min(0), pts.max(0)
        self.extent = float(np.linalg.norm(self.hi - self.lo))
        # Commit now, single-threaded, before any parallel query.
        one = np.zeros((1, 3), np.float32)
        self.embree.run(one, np.array([[0, 0, 1]], np.float32), output=1)

    def intersect(self, origins: np.ndarray, directions: np.ndarray, tfar=None) -> dict:
        """Closest hits of rays (N, 3) float32: {'primID', 'geomID' (-1 for a miss), 'u', 'v', 'tfar'}."""
        d = None if tfar is None else np.array(tfar, np.float32, copy=True)
        return self.embree.run(origins, directions, dists=d, output=1)

    def occluded(self, origins: np.ndarray, directions: np.ndarray, tfar) -> np.ndarray:
        """(N,) bool: something lies along each ray within (0, tfar)."""
        d = np.array(np.broadcast_to(np.asarray(tfar, np.float32), (len(origins),)), np.float32, copy=True)
        return self.embree.run(origins, directions, dists=d, query="OCCLUDED") >= 0

    def matches(self, subject: Subject) -> bool:
        """The same surfaces (same vertex arrays): the scene can be reused."""
        return len(subject.surfaces) == len(self.surfaces) and all(
            a.vertices is b.vertices and a.faces is b.faces for a, b in zip(subject.surfaces, self.surfaces))


def scene_for(subject: Subject, previous: Scene | None = None) -> Scene:
    """`previous` when it holds the same posed surfaces, else a new scene."""
    if previous is not None and previous.matches(subject):
        previous.subject, previous.surfaces = subject, subject.surfaces   # materials may differ
        return previous
    return Scene(subject)
