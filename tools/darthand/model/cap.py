"""The forearm cap: a separate skinned surface that closes the hand mesh's forearm opening, so that packages and
renders show a closed end instead of a hollow tube, while the hand mesh keeps its vertex numbering (MANO's layout;
DART's 842 vertices for a MANO source) and every label stays as it is.

The cap is a fan over the model's longest boundary loop (the forearm cut): one copy of each loop vertex, then the
centre. A loop copy carries its hand vertex's rest position, skin weights, pose correctives and shape directions, so
in every pose and shape it lands exactly on the hand vertex it copies (the seam stays closed); the centre carries
the mean of the loop's, so it moves with the wrist like the loop around it. Faces run against the hand's boundary
edges, so the cap's normals face out of the arm. Per-corner UVs: the two rim corners of a cap triangle take the UVs
their hand vertices have in the hand face along that boundary edge (so each triangle's rim is continuous in UV even
where the loop crosses a UV seam), the centre the mean of the rim's, so the cap shows the skin colour of the rim.

Shapes: L loop vertices, C = L + 1 cap vertices, S shape directions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darthand.errors import InputError
from darthand.model.forward import Posed, pose_feature, skin
from darthand.model.hand_model import HandModel
from darthand.model.topology import boundary_loops, directed_edges

CAP_NAME = "forearm_cap"


@dataclass(frozen=True)
class ForearmCap:
    """vertices (C, 3) rest positions (metres), faces (L, 3) into them, weights (C, 16), posedirs (C, 3, 135),
    shapedirs (C, 3, S), uvs (2 L + 1, 2) and faces_uv (L, 3) per corner or None (the model's convention, v up),
    loop (L,) the hand vertex each of the first L cap vertices copies."""

    vertices: np.ndarray
    faces: np.ndarray
    weights: np.ndarray
    posedirs: np.ndarray
    shapedirs: np.ndarray
    uvs: np.ndarray | None
    faces_uv: np.ndarray | None
    loop: np.ndarray

    def pose(self, posed: Posed, betas=None) -> np.ndarray:
        """(B, C, 3) cap vertices for a `forward` result (its rotations and skinning transforms; `betas` (S,) or
        (B, S) as given to `forward`)."""
        rest = self.vertices[None]
        if betas is not None and self.shapedirs.shape[2]:
            b = np.atleast_2d(np.asarray(betas, dtype=np.float64))
            rest = rest + np.einsum("cks,bs->bck", self.shapedirs[:, :, :b.shape[1]], b)
        B, C = posed.rotations.shape[0], len(self.vertices)
        f = pose_feature(posed.rotations.astype(np.float64))
        offsets = (f @ self.posedirs.transpose(2, 1, 0).reshape(-1, 3 * C)).reshape(B, 3, C)
        return skin(np.ascontiguousarray(self.weights.T), posed.transforms.astype(np.float64),
                    np.swapaxes(rest, 1, 2) + offsets)


def forearm_cap(model: HandModel) -> ForearmCap:
    """The cap closing `model`'s longest boundary loop (InputError if the mesh has no boundary)."""
    loops = boundary_loops(model.faces)
    if not loops:
        raise InputError(f"{model.meta.get('source', 'model')}: the hand mesh has no open end to cap")
    loop = loops[0]
    L = len(loop)
    centre = L
    nxt = np.roll(np.arange(L), -1)
    # The loop runs along its faces' directed edges (a -> b); the cap runs the other way: (b, a, centre).
    faces = np.stack([nxt, np.arange(L), np.full(L, centre)], axis=1)

    def with_centre(a: np.ndarray) -> np.ndarray:
        return np.concatenate([a[loop], a[loop].mean(0, keepdims=True)])

    weights = with_centre(model.weights)
    weights /= weights.sum(axis=1, keepdims=True)
    uvs = faces_uv = None
    if model.has_uvs:
        rim = _rim_uvs(model, loop)                                    # (L, 2, 2): edge i's start and end UVs
        uvs = np.concatenate([rim.reshape(-1, 2), rim[:, 0].mean(0, keepdims=True)])
        faces_uv = np.stack([2 * np.arange(L) + 1, 2 * np.arange(L), np.full(L, 2 * L)], axis=1)
    return ForearmCap(with_centre(model.v_template), faces, weights, with_centre(model.posedirs),
                      with_centre(model.shapedirs), uvs, faces_uv, loop)


def _rim_uvs(model: HandModel, loop: np.ndarray) -> np.ndarray:
    """(L, 2, 2) for each boundary edge loop[i] -> loop[i + 1], the UVs of its two ends in the hand face along it."""
    edges = directed_edges(model.faces).reshape(-1, 3, 2)          # (F, 3, 2): corner k's edge (k -> k + 1)
    starts = {(int(a), int(b)): (f, k) for f, tri in enumerate(edges) for k, (a, b) in enumerate(tri)}
    out = np.empty((len(loop), 2, 2))
    assert model.uvs is not None and model.faces_uv is not None
    for i, v in enumerate(loop):
        f, k = starts[(int(v), int(loop[(i + 1) % len(loop)]))]
        out[i] = model.uvs[model.faces_uv[f, [k, (k + 1) % 3]]]
    return out
