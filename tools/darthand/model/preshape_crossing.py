"""The self-crossing test of model/self_crossing.py with its signed distances through the compiled nearest-point
step (model/pair_kernels.py): the same samples, faces, reach and sign, so the same verdict, at about a third of the
CPU. The two-hand sampler (dataset/interactions.py) tests a pre-shaped hand per frame in the plan's process, where
the vectorised distances cost ~10 ms per digit pair."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from darthand.model.hand_model import HandModel
from darthand.model.pair_kernels import signed_on_candidates
from darthand.model.proximity import FACING_COS, TOUCHING, PartSurfaces, _longest_edge
from darthand.model.self_crossing import SelfCrossing

CANDIDATES = 8      # as PartSurfaces.signed_distances asks of proximity.closest_surface_points


class CompiledPartSurfaces(PartSurfaces):
    """PartSurfaces whose `distance` runs on the compiled step (everything else as indexed by PartSurfaces)."""

    @classmethod
    def of(cls, surfaces: PartSurfaces) -> "CompiledPartSurfaces":
        """The same indexing (rest-time samples and geodesics), not recomputed."""
        out = cls.__new__(cls)
        out.__dict__.update(surfaces.__dict__)
        return out

    def distance(self, vertices: np.ndarray, normals: np.ndarray, p: int, q: int, reach: float = 5e-3) -> float:
        """PartSurfaces.distance: the smallest signed distance (m) between parts p and q both ways, inf beyond
        `reach` (m)."""
        return min(self._smallest(vertices, normals, p, q, reach), self._smallest(vertices, normals, q, p, reach))

    def _smallest(self, vertices, normals, p: int, q: int, reach: float) -> float:
        ids, faces = self.comparable(p, q)
        if len(ids) == 0 or len(faces) == 0:
            return np.inf
        fq = self.faces[faces]
        points = self.samples(vertices, ids)
        d0 = cKDTree(vertices[np.unique(fq)]).query(points, distance_upper_bound=reach + _longest_edge(vertices, fq))[0]
        points = points[np.isfinite(d0)]
        if len(points) == 0:
            return np.inf
        tris = vertices[fq]
        k = min(CANDIDATES, len(fq))
        cand = cKDTree(tris.mean(1)).query(points, k=k)[1].reshape(len(points), k)
        _, _, dist, signed, _, _ = signed_on_candidates(tris, normals[fq], cand, points, FACING_COS, TOUCHING)
        return float(np.where(dist < reach, signed, np.inf).min(initial=np.inf))


class PreshapeCrossing(SelfCrossing):
    """SelfCrossing on CompiledPartSurfaces."""

    def __init__(self, model: HandModel):
        super().__init__(model)
        self.surfaces = CompiledPartSurfaces.of(self.surfaces)
