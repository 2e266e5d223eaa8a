"""Accessories refitted to another hand shape, fast enough to do per frame.

The accessories stage fits every item to one hand (build/model/<side>.npz): a ring's bore to the smallest circle
around its finger's section, a watch's or bracelet's to the smallest axis-aligned ellipse around the forearm's
(fit.py). A dataset that draws a shape per frame needs those fits for each shape. Cutting the shaped mesh again
(`fit_ring` / `fit_wrist`, trimesh plane sections) costs 20-100 ms per item; here the sections are tracked instead:

- once per catalogue (`ShapeRefitter`), each rigid item's section points on the built hand are tied to the
  surface: each point's triangle and barycentric coordinates, so that on a shaped hand the point is the same
  blend of the shaped vertices: P(beta) = P0 + D beta, D = C shapedirs (linear in beta, exact on the surface);
- per shape, the bone frame is made again from the shaped joints (fit.finger_frame / fit.wrist_frame, the
  regressor follows the surface), the tracked points are expressed in it, and the enclosing circle / ellipse gives
  the new bore. The item moves with its fit frame (rest' = F' F^-1 rest) and its bore grows or shrinks by the
  change of radius (rings: every point's radial distance from the bone axis by dr; wrist items: by (da cos t,
  db sin t) at its elliptic angle t), so band widths, thicknesses and ornaments keep their size;
- a glove carries its hand vertices' shape directions (generators/glove.py): its shaped vertices are
  v + shapedirs . beta, exact for the skin-following layers.

Tracking against cutting the shaped mesh again differs where the shape turns the bone relative to the surface (the
tracked points stay on the same skin, the fresh cut is perpendicular to the new bone): the tests bound it (0.6 mm
at |beta| = 3), `make bench` (accessory_shapes) measures it and the time for all 50 items, and `darthand accessories
shapes` the penetration over sampled shapes and the gestures.

Shapes: K section points, V hand vertices, S shape directions, N accessory vertices.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from darthand.accessories.fit import RING_JOINTS, finger_faces, finger_frame, slab_offsets
from darthand.accessories.loader import Accessory
from darthand.accessories.measure import _cut, enclosing_circle, enclosing_ellipse
from darthand.accessories.mesh import frame_matrix
from darthand.errors import InputError
from darthand.model.anatomy import palm_normal, rest_joints
from darthand.model.hand_model import HandModel
from darthand.model.shape import check_betas
from darthand.model.wrist import loop_frame, wrist_loop


@dataclass(frozen=True)
class TrackedSection:
    """The section of one rigid item on the built hand, tied to the surface. kind 'ring' (finger, t) or 'wrist'
    (offset); points0 (K, 3) rest points; D (K, 3, S) their shape directions; bore0 the bore on the built hand
    (inner radius, or (a, b)); frame0 (4, 4) the fit frame there (rest transform of the fitted centre)."""

    kind: str
    finger: str | None
    t: float
    offset: float
    points0: np.ndarray
    D: np.ndarray
    bore0: tuple
    frame0: np.ndarray


class ShapeRefitter:
    """Refits the accessories of one hand (`model`, the built hand they were fitted to) to its shapes."""

    def __init__(self, model: HandModel, accessories: list[Accessory]):
        self.model = model
        self.loop = wrist_loop(model)
        self.accessories = {a.id: a for a in accessories}
        # rigid items without a rest frame (not from a catalogue), or on a joint no fit uses, cannot be placed again:
        # they stay as they are
        keys = {a.id: section_key(model, a, self.loop) for a in accessories
                if not a.skinned and a.rest_transform is not None}
        self.keys = {k: v for k, v in keys.items() if v is not None}
        self._sections: dict = {}

    def section(self, acc_id: str) -> TrackedSection:
        """The tracked section of a rigid accessory (made once, shared by the items that sit alike)."""
        key = self.keys[acc_id]
        if key not in self._sections:
            kind, finger, t, offset, width = key
            self._sections[key] = track_section(self.model, kind, finger, t, offset, width, loop=self.loop)
        return self._sections[key]

    def prepare(self) -> "ShapeRefitter":
        """Track every section now (the one-off cost; otherwise paid at each item's first refit)."""
        for acc_id in self.keys:
            self.section(acc_id)
        return self

    def fit_of(self, acc_id: str, betas) -> tuple[np.ndarray, tuple]:
        """(fit frame (4, 4), bore) of rigid accessory `acc_id` on the hand of `betas`: inner radius (rings) or
        half-axes (a, b) (wrist items), metres, without the accessory's clearance."""
        b = check_betas(self.model, betas)
        return fit_tracked(self.model.shaped(b), self.section(acc_id), b, self.loop)

    def refit(self, betas, ids=None) -> list[Accessory]:
        """The accessories `ids` (default all, catalogue order) fitted to the hand of `betas` (S,), relative to the
        built hand."""
        b = check_betas(self.model, betas)
        if b.ndim != 1:
            raise InputError(f"betas: one shape expected, got shape {b.shape}")
        shaped = self.model.shaped(b)
        fits: dict = {}
        out = []
        for acc_id in (self.accessories if ids is None else ids):
            acc = self.accessories[acc_id]
            if not acc.skinned and acc_id not in self.keys:
                out.append(acc)
                continue
            if acc.skinned:
                moved = acc.vertices if acc.shapedirs is None else \
                    acc.vertices + np.einsum("nks,s->nk", acc.shapedirs[:, :, :len(b)], b)
                out.append(replace(acc, vertices=moved))
                continue
            sec = self.section(acc_id)
            key = self.keys[acc_id]
            if key not in fits:
                fits[key] = fit_tracked(shaped, sec, b, self.loop)
            out.append(replace(acc, vertices=reshaped_vertices(acc, sec, *fits[key])))
        return out


def section_key(model: HandModel, acc: Accessory, loop: np.ndarray) -> tuple | None:
    """(kind, finger, t, offset, width) of where a rigid accessory sits, read back from its rest transform and
    local extent (the same on the built hand as when it was fitted); None for an item on a joint the fits do not
    use (not the wrist, not a finger's first joint: a user's item on a middle phalanx), which keeps its shape."""
    if acc.parent_joint != 0 and acc.parent_joint not in RING_JOINTS.values():
        return None
    rest = acc.rest_transform
    assert rest is not None, "rigid accessories have a rest transform"
    local = (acc.vertices - rest[:3, 3]) @ rest[:3, :3]
    width = round(float(2 * np.abs(local[:, 0]).max()), 5)
    if acc.parent_joint == 0:
        j0, axis = wrist_axis(model, loop)
        return ("wrist", None, 0.0, round(float((rest[:3, 3] - j0) @ axis), 5), width)
    finger = next(f for f, j in RING_JOINTS.items() if j == acc.parent_joint)
    frame = finger_frame(model, finger, 0.0)
    end = finger_frame(model, finger, 1.0)
    length = float(np.linalg.norm(end[:3, 3] - frame[:3, 3]))
    t = float((rest[:3, 3] - frame[:3, 3]) @ frame[:3, 0]) / length
    return ("ring", finger, round(t, 4), 0.0, width)


def track_section(model: HandModel, kind: str, finger: str | None, t: float, offset: float,
                  width: float, loop: np.ndarray) -> TrackedSection:
    """Cut the built hand where the item sits (as fit.py does) and tie the section points to the surface."""
    if kind == "ring":
        assert finger is not None, "a ring sits on a finger"
        bone = finger_frame(model, finger, t)
        own = finger_faces(model, RING_JOINTS[finger])
    else:
        bone, own = wrist_frame(model, offset, loop), None
    local = (model.v_template - bone[:3, 3]) @ bone[:3, :3]
    pts3 = []
    for faces in ([] if own is None else [model.faces[own]]) + [model.faces]:   # the finger's own skin first
        cut_mesh = trimesh.Trimesh(local, faces, process=False)
        for x in slab_offsets(width):  # plane by plane (each point's plane known); planes without a loop are
            pts2 = _cut(cut_mesh, x)   # skipped, as fit_ring does (a plane reaching into the finger's web)
            if pts2 is not None:
                pts3.append(bone[:3, 3] + x * bone[:3, 0] + pts2 @ bone[:3, 1:3].T)
        if pts3:
            break
    if not pts3:
        raise InputError(f"{kind} section: no closed loop around the {finger or 'forearm'} axis")
    closest, tri = on_surface(model, np.concatenate(pts3))
    bary = trimesh.triangles.points_to_barycentric(model.v_template[model.faces[tri]], closest)
    corners = model.faces[tri]                                                         # (K, 3)
    D = np.einsum("kc,kcxs->kxs", bary, model.shapedirs[corners])
    sec = TrackedSection(kind, finger, t, offset, closest, D, (), bone)
    frame, bore = _fit_points(model, sec, closest, loop)
    return replace(sec, bore0=bore, frame0=frame)


def on_surface(model: HandModel, points: np.ndarray, k: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Closest surface points (K, 3) of points on or near the rest surface and their triangles (K,): the nearest
    of the k triangles whose centroids are nearest."""
    tris = model.v_template[model.faces]
    _, cand = cKDTree(tris.mean(1)).query(points, k=k)
    best = np.full(len(points), np.inf)
    closest, tri = np.zeros_like(points), np.zeros(len(points), np.int64)
    for c in cand.T:
        p = trimesh.triangles.closest_point(tris[c], points)
        d = np.linalg.norm(p - points, axis=1)
        better = d < best
        best[better], closest[better], tri[better] = d[better], p[better], c[better]
    return closest, tri


def _fit_points(model: HandModel, sec: TrackedSection, points: np.ndarray,
                loop: np.ndarray) -> tuple[np.ndarray, tuple]:
    """The fit frame (rest transform of the fitted centre) and bore of tracked points on a hand."""
    bone = finger_frame(model, sec.finger, sec.t) if sec.finger is not None else wrist_frame(model, sec.offset, loop)
    # The item sits where its tracked skin is: along the bone at the points' mean, which on another shape need
    # not be the same fraction of the phalanx or distance from the wrist (a forearm tapers).
    bone[:3, 3] += float(((points - bone[:3, 3]) @ bone[:3, 0]).mean()) * bone[:3, 0]
    yz = (points - bone[:3, 3]) @ bone[:3, 1:3]
    if sec.kind == "ring":
        centre, r = enclosing_circle(yz)
        bore = (r,)
    else:
        centre, a, b = enclosing_ellipse(yz)
        bore = (a, b)
    frame = bone.copy()
    frame[:3, 3] = bone[:3, 3] + centre[0] * bone[:3, 1] + centre[1] * bone[:3, 2]
    return frame, bore


def fit_tracked(shaped: HandModel, sec: TrackedSection, betas: np.ndarray,
                loop: np.ndarray) -> tuple[np.ndarray, tuple]:
    """Fit frame and bore on a shaped hand from the tracked points P0 + D beta."""
    pts = sec.points0 + np.einsum("kxs,s->kx", sec.D[:, :, :len(betas)], betas)
    return _fit_points(shaped, sec, pts, loop)


def reshaped_vertices(acc: Accessory, sec: TrackedSection, frame: np.ndarray, bore: tuple) -> np.ndarray:
    """The accessory's rest vertices for a new fit frame and bore: moved with the frame, its bore grown or shrunk
    by the change of radius (see the module docstring)."""
    fit_local = (acc.vertices - sec.frame0[:3, 3]) @ sec.frame0[:3, :3]              # in the old fit frame
    yz = fit_local[:, 1:]
    if sec.kind == "ring":
        dr = bore[0] - sec.bore0[0]
        r = np.maximum(np.linalg.norm(yz, axis=1, keepdims=True), 1e-9)
        yz = yz + dr * yz / r
    else:
        (a0, b0), (a1, b1) = sec.bore0, bore
        th = np.arctan2(yz[:, 1] / b0, yz[:, 0] / a0)
        yz = yz + np.stack([(a1 - a0) * np.cos(th), (b1 - b0) * np.sin(th)], axis=1)
    local = np.concatenate([fit_local[:, :1], yz], axis=1)
    return frame[:3, 3] + local @ frame[:3, :3].T


def wrist_axis(model: HandModel, loop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """fit.wrist_axis with the wrist loop given (finding it costs more than the whole refit)."""
    return rest_joints(model)[0], loop_frame(model, loop)[1]


def wrist_frame(model: HandModel, offset: float, loop: np.ndarray) -> np.ndarray:
    """fit.wrist_frame with the wrist loop given."""
    j0, axis = wrist_axis(model, loop)
    return frame_matrix(j0 + offset * axis, axis, -palm_normal(model))
