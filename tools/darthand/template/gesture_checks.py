"""Checks of a model posed in every named gesture: finite vertices, inverted triangles, self-intersections.

Inverted triangles. A face is inverted when its posed normal points against the normal it should have: the rest
normal turned by the face's own skinning rotation, the polar (nearest) rotation of its blended linear part
sum_j w_j R_j with the weights averaged over its three corners. Comparing with that rotation rather than with the
dominant joint's keeps faces in a bent crease, which legitimately turn by a fraction of the bend, from counting as
flipped; only faces folded over by the skinning do. Faces whose posed area collapses to ~0 are counted apart.

Self-intersections are MeshLab's (pymeshlab `compute_selection_by_self_intersections_per_face`, which ignores
neighbouring faces). Each face belongs to the part of its dominant joint: the palm (joint 0) or one of the five
digits. A face intersecting a face of another part is found by running the filter on the two parts together and
keeping the faces not already selected within either part alone. (MeshLab can flag exactly coplanar, disjoint
triangles, as on a polygonal cylinder's flat strips; a skinned hand has none.)
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pymeshlab

from darthand.fileio import write_json
from darthand.model.forward import forward
from darthand.model.hand_model import HandModel
from darthand.model.layout import FINGER_JOINTS, FINGERS, NUM_JOINTS
from darthand.model.poses import gesture_poses
from darthand.model.preview import HIGHLIGHT, SKIN, contact_sheet, render_mesh, write_png
from darthand.model.topology import face_joints

PARTS = ("palm",) + FINGERS
DEGENERATE_AREA = 1e-12  # m^2 (1 mm^2 = 1e-6 m^2)


def joint_parts() -> np.ndarray:
    """(16,) index into PARTS of each joint: 0 palm (the root), else its digit."""
    part = np.zeros(NUM_JOINTS, dtype=np.int64)
    for k, finger in enumerate(FINGERS):
        part[list(FINGER_JOINTS[finger])] = k + 1
    return part


def face_parts(model: HandModel) -> np.ndarray:
    """(F,) index into PARTS of each face: the part of the joint with the largest summed corner weight."""
    return joint_parts()[face_joints(model.faces, model.weights)]


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(..., F, 3) area-weighted face normals (cross products, twice the area long) of vertices (..., V, 3)."""
    a, b, c = (vertices[..., faces[:, k], :] for k in range(3))
    return np.cross(b - a, c - a)


def face_rotations(model: HandModel, world_rotations: np.ndarray) -> np.ndarray:
    """(B, F, 3, 3) nearest rotation to each face's blended linear part, world_rotations (B, 16, 3, 3)."""
    w = model.weights[model.faces].mean(axis=1)                              # (F, 16)
    M = np.einsum("fj,bjkl->bfkl", w, world_rotations)
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))                                       # keep proper rotations
    U[..., :, 2] *= d[..., None]
    return U @ Vt


def inverted_faces(model: HandModel, vertices: np.ndarray,
                   world_rotations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(B, F) bool inverted and (B, F) bool degenerate faces of posed vertices (B, V, 3)."""
    rest = face_normals(model.v_template, model.faces)                      # (F, 3)
    posed = face_normals(vertices, model.faces)                              # (B, F, 3)
    expected = np.einsum("bfkl,fl->bfk", face_rotations(model, world_rotations), rest)
    degenerate = np.linalg.norm(posed, axis=-1) < 2 * DEGENERATE_AREA
    return (np.einsum("bfk,bfk->bf", posed, expected) < 0) & ~degenerate, degenerate


def self_intersecting(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) bool faces that intersect another, non-adjacent face (pymeshlab)."""
    if len(faces) == 0:
        return np.zeros(0, dtype=bool)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.asarray(vertices, dtype=np.float64), face_matrix=faces))
    ms.compute_selection_by_self_intersections_per_face()
    return ms.current_mesh().face_selection_array().astype(bool)


def intersections_within_parts(vertices: np.ndarray, faces: np.ndarray,
                               parts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F,) bool faces intersecting anything, and (F,) bool faces intersecting a face of their own part."""
    everywhere = self_intersecting(vertices, faces)
    alone = np.zeros(len(faces), dtype=bool)
    if everywhere.any():
        for p in np.unique(parts):
            alone[parts == p] = self_intersecting(vertices, faces[parts == p])
    return everywhere, alone


def part_intersections(vertices: np.ndarray, faces: np.ndarray, parts: np.ndarray, masks=None) -> dict:
    """Self-intersections of one posed mesh (V, 3), split by part (masks: its `intersections_within_parts`, when
    already computed).

    Returns {"faces": all self-intersecting faces, "within": {part: faces intersecting their own part},
    "between": {"a-b": faces of a or b that intersect the other part}} (counts).
    """
    everywhere, alone = intersections_within_parts(vertices, faces, parts) if masks is None else masks
    out = {"faces": int(everywhere.sum()),
           "within": {PARTS[p]: int(alone[parts == p].sum()) for p in np.unique(parts[alone])},
           "between": {}}
    for p, q in itertools.combinations(np.unique(parts[everywhere & ~alone]), 2):
        pair = (parts == p) | (parts == q)
        hit = self_intersecting(vertices, faces[pair]) & ~alone[pair]
        if hit.any():
            out["between"][f"{PARTS[p]}-{PARTS[q]}"] = int(hit.sum())
    return out


def gesture_report(model: HandModel, names: list[str] | None = None, poses_dir=None) -> dict:
    """Per gesture: NaN check, inverted/degenerate triangle counts and self-intersection counts.

    {name: {"finite": bool, "inverted_faces": n, "degenerate_faces": n, "self_intersecting_faces": n,
            "between_fingers_faces": n (faces of one digit intersecting another digit),
            "finger_palm_faces": n (digit-palm), "within": {...}, "between": {...}}}
    """
    return checked_gestures(model, names, poses_dir)[3]


def checked_gestures(model: HandModel, names: list[str] | None = None, poses_dir=None) -> tuple:
    """(names, posed vertices (G, V, 3), crossing (G, F) bool: faces intersecting another part of the hand,
    `gesture_report`): what the report and the contact sheet both need, computed once."""
    names, poses = gesture_poses(model, names, poses_dir)
    posed = forward(model, poses)
    inverted, degenerate = inverted_faces(model, posed.vertices, posed.world_rotations)
    parts = face_parts(model)
    report = {}
    crossing = np.zeros((len(names), model.num_faces), bool)
    for g, name in enumerate(names):
        v = posed.vertices[g]
        finite = bool(np.isfinite(v).all())
        entry = {"finite": finite, "inverted_faces": int(inverted[g].sum()),
                 "degenerate_faces": int(degenerate[g].sum())}
        if finite:
            everywhere, alone = masks = intersections_within_parts(v, model.faces, parts)
            crossing[g] = everywhere & ~alone
            inter = part_intersections(v, model.faces, parts, masks)
            between = inter["between"]
            entry.update(
                self_intersecting_faces=inter["faces"],
                between_fingers_faces=sum(n for k, n in between.items() if "palm" not in k),
                finger_palm_faces=sum(n for k, n in between.items() if "palm" in k),
                within=inter["within"], between=between)
        report[name] = entry
    return names, posed.vertices, crossing, report


def gesture_problems(report: dict, max_between_fingers: int = 10) -> list[str]:
    """One line per failed check in a `gesture_report`: non-finite vertices, inverted triangles, more than
    `max_between_fingers` faces where two digits intersect."""
    problems = []
    for name, r in report.items():
        if not r["finite"]:
            problems.append(f"gesture '{name}': non-finite vertices")
            continue
        if r["inverted_faces"]:
            problems.append(f"gesture '{name}': {r['inverted_faces']} inverted triangles")
        if r["between_fingers_faces"] > max_between_fingers:
            pairs = ", ".join(f"{k} {n}" for k, n in r["between"].items() if "palm" not in k)
            problems.append(f"gesture '{name}': {r['between_fingers_faces']} faces where digits intersect ({pairs}), "
                            f"more than {max_between_fingers}")
    return problems


def write_gesture_checks(model: HandModel, out_dir: str | Path, names: list[str] | None = None) -> dict:
    """Write `gestures.json` (the `gesture_report`) and `gestures.png` (the contact sheet) into `out_dir`;
    return the report."""
    out_dir = Path(out_dir)
    checked = checked_gestures(model, names)
    write_json(out_dir / "gestures.json", {"model": model.meta.get("source"), "gestures": checked[3]})
    write_gesture_sheet(model, out_dir / "gestures.png", checked=checked)
    return checked[3]


def write_gesture_sheet(model: HandModel, out_png: str | Path, names: list[str] | None = None, *, checked=None,
                        views=("three_quarter", "radial", "palmar"), size: int = 256,
                        cols: int | None = None) -> list[str]:
    """Render every named gesture of `model` from `views` into one contact sheet PNG, the faces that intersect
    another part of the hand in red; return the gesture names. checked: `checked_gestures` (computed when not
    given). cols: tiles per row (default: two gestures per row)."""
    names, vertices, crossing, _ = checked if checked is not None else checked_gestures(model, names)
    images, labels = [], []
    for name, v, cross in zip(names, vertices, crossing):
        colors = np.tile(SKIN, (model.num_faces, 1))
        colors[cross] = HIGHLIGHT
        for view in views:
            images.append(render_mesh(v, model.faces, view=view, size=size, face_colors=colors, side=model.side))
            labels.append(name if len(views) == 1 else f"{name} ({view})")
    write_png(out_png, contact_sheet(images, labels, cols or 2 * len(views)))
    return names
