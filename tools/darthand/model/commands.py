"""The `darthand model ...` commands: each takes parsed arguments, calls the stage, prints a short report.

Each handler imports lazily what only it uses, so that building the CLI (and `darthand --help`) loads none of it.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import atomic_path
from darthand.model.atlas import ensure_uvs
from darthand.model.forward import forward
from darthand.model.gesture_fit import with_fitted_gestures
from darthand.model.hand_model import HandModel
from darthand.model.load import load_model
from darthand.model.mirror import mirror_model
from darthand.model.npz_io import save_npz
from darthand.model.regions import ensure_face_labels
from darthand.model.topology import boundary_loops, non_manifold_edges
from darthand.model.wrist import add_wrist


def describe(model: HandModel) -> dict:
    """Counts and properties of a model, as `model info --json` prints them."""
    loops = boundary_loops(model.faces)
    return {
        "source": model.meta.get("source"),
        "side": model.side,
        "vertices": model.num_vertices,
        "faces": model.num_faces,
        "joints": int(model.parents.shape[0]),
        "correctives": int(model.posedirs.shape[2]),
        "nonzero_correctives": int(np.count_nonzero(np.abs(model.posedirs).max(axis=(0, 1)))),
        "shape_dims": model.num_betas,
        "boundary_loops": [len(loop) for loop in loops],
        "non_manifold_edges": int(len(non_manifold_edges(model.faces))),
        "has_uvs": model.has_uvs,
        "has_face_labels": model.face_labels is not None,
        "tip_ids": model.tip_ids.tolist(),
        "wrist": {k: v for k, v in model.meta["wrist"].items() if k != "loop"} if "wrist" in model.meta else None,
        "fixes": model.meta.get("fixes", []),
    }


def info(args) -> int:
    d = describe(load_model(args.model))
    if args.json:
        print(json.dumps(d, indent=2))
        return 0
    print(f"{d['source']}: {d['side']} hand, {d['vertices']} vertices, {d['faces']} faces, {d['joints']} joints")
    print(f"  correctives {d['correctives']} ({d['nonzero_correctives']} non-zero), shape dims {d['shape_dims']}")
    print(f"  boundary loops {d['boundary_loops']}, non-manifold edges {d['non_manifold_edges']}, "
          f"UVs {'yes' if d['has_uvs'] else 'no'}, face labels {'yes' if d['has_face_labels'] else 'no'}")
    if d["wrist"]:
        print(f"  wrist: {d['wrist']['rings']} rings of {d['wrist']['ring_size']} added to "
              f"{d['wrist']['base_vertices']} vertices")
    for fix in d["fixes"]:
        print(f"  fixed on load: {fix}")
    return 0


def pose(args) -> int:
    from darthand.model.poses import load_pose_file

    model = load_model(args.model)
    poses, betas, flat_hand_mean = load_pose_file(args.pose)
    dtype = np.dtype(args.dtype)
    posed = forward(model, poses, betas, flat_hand_mean=flat_hand_mean, dtype=dtype, keypoint_order="openpose")
    buf = io.BytesIO()
    np.savez(buf, vertices=posed.vertices, joints=posed.joints, keypoints=posed.keypoints)
    with atomic_path(args.out) as tmp:
        tmp.write_bytes(buf.getvalue())
    print(f"{args.out}: {posed.vertices.shape[0]} poses, {model.num_vertices} vertices, {dtype.name}")
    return 0


def wrist(args) -> int:
    model = add_wrist(load_model(args.model), rings=args.rings, length=args.length, taper=args.taper,
                      anchor=args.anchor, smooth=args.smooth)
    save_npz(model, args.out)
    w = model.meta["wrist"]
    print(f"{args.out}: {w['base_vertices']} -> {model.num_vertices} vertices, {w['base_faces']} -> "
          f"{model.num_faces} faces ({w['rings']} rings of {w['ring_size']}, anchor {w['anchor']})")
    return 0


def build(args) -> int:
    """The pipeline's model step: the wrist-enhanced model of each side, as build/model/{right,left}.npz.

    A model without UVs (MANO) gets a deterministic xatlas atlas for textures of `--atlas-res` texels, made once on
    the wrist-enhanced mesh and mirrored with it, so textures, USD and glTF all use the same UVs; a model without
    face labels gets labels derived from its geometry (`regions.derive_face_labels`). Every named gesture is fitted
    to the model and recorded in it (`gesture_fit`), so every later stage poses the same collision-free gestures.
    """
    source = load_model(args.model)
    enhanced = ensure_uvs(add_wrist(source), args.atlas_res)
    right = enhanced if enhanced.side == "right" else mirror_model(enhanced)
    betas = parse_betas(getattr(args, "betas", None))
    if betas is not None:               # the shape first: gestures are fitted to the hand they will pose
        right = right.shaped(betas)
    right = with_fitted_gestures(ensure_face_labels(right))
    out = Path(args.out_dir)
    for model in (right, mirror_model(right)):
        save_npz(model, out / f"{model.side}.npz")
    for fix in source.meta.get("fixes", []):
        print(f"  fixed on load: {fix}")
    uv = "xatlas atlas" if "uv_atlas" in right.meta else "the template's UVs"
    labels = "derived face labels" if source.face_labels is None else "the template's face labels"
    status = [g["status"] for g in right.meta["gestures"]["gestures"].values()]
    fits = ", ".join(f"{status.count(s)} {s}" for s in ("kept", "fitted", "unresolved") if s in status)
    shape = f"; shape betas {' '.join(f'{b:g}' for b in betas)}" if betas is not None else ""
    print(f"{out}/right.npz, left.npz: {right.num_vertices} vertices, {right.num_faces} faces "
          f"(from {args.model}, {source.num_vertices} vertices; {uv}; {labels}{shape}); gestures: {fits}")
    return 0


def parse_betas(text: str | None) -> np.ndarray | None:
    """'1.5 -0.5' or '1.5,-0.5' -> array([1.5, -0.5]); None or blank -> None; InputError naming a bad entry."""
    if text is None or not str(text).strip():
        return None
    values = []
    for item in str(text).replace(",", " ").split():
        try:
            values.append(float(item))
        except ValueError:
            raise InputError(f"--betas: {item!r} is not a number") from None
    return np.asarray(values)


def fit_library(args) -> int:
    """`model fit-library`: the pose library fitted to a model, written as a fit record (model/library_fit)."""
    from darthand.model.library_fit import earlier_fit, fit_library as fit, select_poses, write_fit   # MeshLab

    model = load_model(args.model)
    previous = None if args.no_reuse else earlier_fit(args.out)
    record = fit(model, select_poses(args.poses), jobs=args.jobs, previous=previous)
    write_fit(args.out, record)
    status = [p["status"] for p in record["poses"].values()]
    fits = ", ".join(f"{status.count(s)} {s}" for s in ("kept", "fitted", "unresolved") if s in status)
    reused = f", {record['reused']} of them unchanged since the last fit" if record["reused"] else ""
    print(f"{args.out}: {len(status)} library poses fitted to {model.meta.get('source', args.model)} in "
          f"{record['seconds']:.0f} s ({fits}{reused})")
    return 0


def library_sheet(args) -> int:
    """`model library-sheet`: the pose library drawn on a model, one contact sheet per group."""
    from darthand.model.library_fit import fitted_poses, model_library
    from darthand.model.library_sheet import library_sheets

    model = load_model(args.model)
    poses = fitted_poses(model, fit=args.fit, beside=args.model)
    library = model_library(model, fit=args.fit, poses=poses, beside=args.model)
    for path in library_sheets(model, library, args.out_dir):
        print(path)
    return 0
