"""`darthand eval PRED GT`: read predictions and ground truth in the forms training code writes, and compute
FreiHAND's figures (dataset/metrics.py); per-hand predictions and two-hand frames: dataset/evaluate_hands.py.

Forms: a darthand dataset folder (labels' keypoints_3d and meshes/ vertices, the hand without the wrist rings, in
frame order); a FreiHAND set (a folder with <set>_xyz.json and <set>_verts.json, or one of those files); FreiHAND's
pred.json ([keypoints per sample, vertices per sample]); an .npz with 'keypoints' (B, 21, 3) and optionally
'vertices' (B, V, 3). Metres throughout. A prediction with more vertices than the ground truth is cut to the first
ones (darthand's full mesh against the hand without the wrist rings, which come first).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from darthand.dataset.evaluate_hands import evaluate_hands, hands_markdown, is_hand_predictions
from darthand.dataset.frames import frame_names
from darthand.dataset.hands import is_multi_hand
from darthand.dataset.metrics import evaluate
from darthand.dataset.run import read_shard_records
from darthand.errors import InputError
from darthand.fileio import read_json, write_bytes, write_json


def load_points(path) -> tuple[np.ndarray, np.ndarray | None]:
    """(keypoints (B, 21, 3), vertices (B, V, 3) or None) of a file or folder in one of the module's forms."""
    path = Path(path)
    if path.is_dir() and (path / "dataset.json").is_file():
        return _dataset_points(path)
    if path.is_dir():
        xyz = sorted(path.glob("*_xyz.json"))
        if not xyz:
            raise InputError(f"{path}: neither a darthand dataset nor a FreiHAND set (*_xyz.json)")
        if len(xyz) > 1:
            xyz = [p for p in xyz if p.name == "evaluation_xyz.json"] or xyz[:1]
        return _freihand_points(xyz[0])
    if path.suffix == ".npz":
        try:
            with np.load(path, allow_pickle=False) as z:
                kp = np.asarray(z["keypoints"], np.float64)
                verts = np.asarray(z["vertices"], np.float64) if "vertices" in z.files else None
        except (OSError, ValueError, KeyError) as e:
            raise InputError(f"{path}: cannot read keypoints/vertices ({e})") from None
        return _checked(path, kp, verts)
    if path.name.endswith("_xyz.json"):
        return _freihand_points(path)
    doc = read_json(path, "predictions file")
    if not (isinstance(doc, list) and len(doc) == 2):
        raise InputError(f"{path}: FreiHAND's pred.json is [keypoints per sample, vertices per sample]")
    return _checked(path, _array(path, doc[0], "0"), _array(path, doc[1], "1") if doc[1] else None)


def _array(path, value, field) -> np.ndarray:
    try:
        return np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{path}: field '{field}' is not an array of numbers") from None


def _checked(path, kp: np.ndarray, verts: np.ndarray | None):
    if kp.ndim != 3 or kp.shape[1:] != (21, 3):
        raise InputError(f"{path}: keypoints have shape {kp.shape}, expected (samples, 21, 3)")
    if verts is not None and (verts.ndim != 3 or verts.shape[2] != 3 or len(verts) != len(kp)):
        raise InputError(f"{path}: vertices have shape {verts.shape}, expected ({len(kp)}, V, 3)")
    for name, a in (("keypoints", kp), ("vertices", verts)):
        if a is not None and not np.isfinite(a).all():
            raise InputError(f"{path}: {name} hold a non-finite value")
    return kp, verts


def _freihand_points(xyz_path: Path):
    kp = _array(xyz_path, read_json(xyz_path, "FreiHAND keypoints"), "xyz")
    verts_path = xyz_path.with_name(xyz_path.name.replace("_xyz.json", "_verts.json"))
    verts = _array(verts_path, read_json(verts_path, "FreiHAND vertices"), "verts") if verts_path.is_file() else None
    return _checked(xyz_path, kp, verts)


def _dataset_points(folder: Path):
    frames = read_shard_records(folder)
    if not frames:
        raise InputError(f"{folder}: no rendered frames")
    kps, verts = [], []
    for f in frames:
        names = frame_names(f["index"])
        labels = read_json(folder / names["labels"], "labels")
        kps.append(labels["keypoints_3d"])
        verts.append(np.load(folder / names["vertices"])[:labels["mesh"]["base_vertices"]])
    return _checked(folder, np.asarray(kps, np.float64), np.asarray(verts, np.float64))


def evaluate_files(pred, gt, out=None) -> dict:
    """The figures of predictions `pred` against ground truth `gt` (paths in the module's forms); with `out`, also
    written to out/eval.json and out/eval.md. Per-hand predictions (dataset/evaluate_hands.py), or a dataset
    against a dataset with two-hand frames, get per-side figures and MRRPE instead."""
    if is_hand_predictions(pred) or _has_two_hands(gt):
        if not (is_hand_predictions(pred) or Path(pred, "dataset.json").is_file()):
            raise InputError(f"{pred}: the ground truth {gt} holds two-hand frames: give per-hand predictions "
                             f"(schemas/hand_predictions.schema.json) or a dataset folder")
        result = evaluate_hands(pred, gt)
        if out is not None:
            write_json(Path(out) / "eval.json", result)
            write_bytes(Path(out) / "eval.md", hands_markdown(result).encode())
        return result
    pk, pv = load_points(pred)
    gk, gv = load_points(gt)
    if len(pk) != len(gk):
        raise InputError(f"{pred}: {len(pk)} samples, the ground truth {gt} has {len(gk)}")
    if pv is not None and gv is not None:
        if pv.shape[1] < gv.shape[1]:
            raise InputError(f"{pred}: {pv.shape[1]} vertices per sample, the ground truth has {gv.shape[1]}")
        pv = pv[:, :gv.shape[1]]
    result = {"pred": str(pred), "gt": str(gt), **evaluate(pk, gk, pv, gv)}
    if out is not None:
        write_json(Path(out) / "eval.json", result)
        write_bytes(Path(out) / "eval.md", markdown_table(result).encode())
    return result


def _has_two_hands(path) -> bool:
    """Whether `path` is a dataset folder holding a two-hand frame (its shard records' hand_type, else labels)."""
    path = Path(path)
    if not (path.is_dir() and (path / "dataset.json").is_file()):
        return False
    for f in read_shard_records(path):
        labels = read_json(path / frame_names(f["index"])["labels"], "labels")
        if is_multi_hand(labels):
            return True
    return False


def markdown_table(result: dict) -> str:
    if "per_side" in result:
        return hands_markdown(result)
    lines = [f"# darthand eval: {result['samples']} samples", "", "| figure | value |", "|---|---|"]
    for group in ("keypoints", "vertices"):
        for key, value in result.get(group, {}).items():
            lines.append(f"| {group} {key} | {value} |")
    return "\n".join(lines) + "\n"


def write_predictions(path, keypoints, vertices=None) -> None:
    """FreiHAND's pred.json: [keypoints per sample, vertices per sample] (lists, metres)."""
    write_bytes(path, json.dumps([np.asarray(keypoints).tolist(),
                                  [] if vertices is None else np.asarray(vertices).tolist()]).encode())
