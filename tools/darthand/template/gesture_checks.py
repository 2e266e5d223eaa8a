"""Checks of a model posed in every named gesture: finite vertices, inverted triangles, self-intersections,
contact distances -- the guard of the gestures fitted to the model (model/gesture_fit), with the authored angles'
figures beside them ("before") and the left mirror's checks.

Inverted triangles. A face is inverted when its posed normal points against the normal it should have: the rest
normal turned by the face's own skinning rotation, the polar (nearest) rotation of its blended linear part
sum_j w_j R_j with the weights averaged over its three corners. Comparing with that rotation rather than with the
dominant joint's keeps faces in a bent crease, which legitimately turn by a fraction of the bend, from counting as
flipped; only faces folded over by the skinning do. Faces whose posed area collapses to ~0 are counted apart.

Self-intersections between parts of the hand: `darthand.model.intersections` (MeshLab's per-face test).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from darthand.fileio import write_json
from darthand.model.forward import forward
from darthand.model.gestures import fitted_record, model_gestures
from darthand.model.hand_model import HandModel
from darthand.model.intersections import (PARTS, between_digits, face_parts, intersections_within_parts,
                                          part_intersections)
from darthand.model.mirror import mirror_model
from darthand.model.poses import gesture_contacts, gesture_poses
from darthand.model.preview import HIGHLIGHT, SKIN, contact_sheet, render_mesh, write_png
from darthand.model.proximity import PartSurfaces
from darthand.template.gesture_problems import MIRROR_FIELDS
from darthand.model.topology import vertex_normals

DEGENERATE_AREA = 1e-12  # m^2 (1 mm^2 = 1e-6 m^2)


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


def gesture_report(model: HandModel, names: list[str] | None = None, poses_dir=None) -> dict:
    """Per gesture of `model` (`model.gestures.model_gestures`: fitted to it when it carries a fit): NaN check,
    inverted/degenerate triangle counts, self-intersection counts, contact distances; for fitted gestures also
    the same figures for the authored angles ("before") and the fit's record; the left mirror's checks.

    {name: {"finite": bool, "inverted_faces": n, "degenerate_faces": n, "self_intersecting_faces": n,
            "between_fingers_faces": n (faces of one digit intersecting another digit),
            "finger_palm_faces": n (digit-palm), "within": {...}, "between": {...},
            "contacts": {"a-b": mm} (intended contacts: smallest signed distance, negative = passing through),
            "closest": {"pair": "a-b", "mm": x} or None (the nearest two parts not meant to touch, within 5 mm),
            "fit": {"status", "changed_deg", "at_bound", "clearance_mm"}, "before": {...}, "mirror": {...}}}
    """
    return checked_gestures(model, names, poses_dir)[3]


def checked_gestures(model: HandModel, names: list[str] | None = None, poses_dir=None) -> tuple:
    """(names, posed vertices (G, V, 3), crossing (G, F) bool: faces intersecting another part of the hand,
    `gesture_report`): what the report and the contact sheet both need, computed once."""
    gestures = model_gestures(model, names, poses_dir)
    names = list(gestures.names)
    record = fitted_record(model)
    fits = record["gestures"] if record is not None and gestures.fitted else None
    contacts = [fits[n]["contacts"] if fits is not None else gesture_contacts(n, poses_dir) for n in names]
    surfaces = PartSurfaces(model)
    vertices, crossing, report = pose_checks(model, gestures.poses, names, contacts, surfaces)
    if fits is not None:
        _, authored = gesture_poses(model, names)
        before = pose_checks(model, authored, names, contacts, surfaces)[2]
        for name in names:
            fit = fits[name]
            report[name]["fit"] = {k: fit[k] for k in ("status", "changed_deg", "at_bound", "clearance_mm")}
            report[name]["before"] = {k: before[name].get(k) for k in BEFORE_FIELDS}
    mirror = mirror_model(model)
    mirrored = pose_checks(mirror, model_gestures(mirror, names, poses_dir).poses, names)[2]
    for name in names:
        report[name]["mirror"] = dict({k: mirrored[name].get(k) for k in MIRROR_FIELDS}, side=mirror.side)
    return names, vertices, crossing, report


BEFORE_FIELDS = ("inverted_faces", "between_fingers_faces", "finger_palm_faces", "between", "contacts", "closest")


def pose_checks(model: HandModel, poses: np.ndarray, names: list[str], contacts: list | None = None,
                surfaces: PartSurfaces | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """The checks of poses (G, 48) named `names`: (posed vertices (G, V, 3), crossing (G, F), {name: entry}).
    With `contacts` (per pose, pairs of part names) and `surfaces`, entries also get contact and closest
    distances."""
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
                self_intersecting_faces=inter["faces"], between_fingers_faces=between_digits(between),
                finger_palm_faces=sum(n for k, n in between.items() if "palm" in k),
                within=inter["within"], between=between)
            if surfaces is not None and contacts is not None:
                entry.update(part_distances(surfaces, v, model.faces, contacts[g]))
        report[name] = entry
    return posed.vertices, crossing, report


def part_distances(surfaces: PartSurfaces, vertices: np.ndarray, faces: np.ndarray, contacts: list) -> dict:
    """{"contacts": {"a-b": mm} for the intended contacts, "closest": {"pair", "mm"} of the nearest two parts
    not meant to touch (None when none come within 5 mm)}; signed distances, negative = passing through."""
    normals = vertex_normals(vertices, faces)
    meant = {tuple(sorted(PARTS.index(p) for p in pair)) for pair in contacts}
    out: dict = {"contacts": {}, "closest": None}
    for p, q in itertools.combinations(range(len(PARTS)), 2):
        d = surfaces.distance(vertices, normals, p, q)
        if (p, q) in meant:
            out["contacts"][f"{PARTS[p]}-{PARTS[q]}"] = round(d * 1e3, 3) if np.isfinite(d) else None
        elif np.isfinite(d) and (out["closest"] is None or d * 1e3 < out["closest"]["mm"]):
            out["closest"] = {"pair": f"{PARTS[p]}-{PARTS[q]}", "mm": round(d * 1e3, 3)}
    return out


def write_gesture_checks(model: HandModel, out_dir: str | Path, names: list[str] | None = None) -> dict:
    """Write `gestures.json` (the `gesture_report`) and `gestures.png` (the contact sheet) into `out_dir`;
    return the report."""
    out_dir = Path(out_dir)
    checked = checked_gestures(model, names)
    write_json(out_dir / "gestures.json", {"model": model.meta.get("source"),
                                           "fitted": fitted_record(model) is not None, "gestures": checked[3]})
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
