"""`darthand eval` of per-hand predictions, the form two-hand frames need (schemas/hand_predictions.schema.json):

    {"format": "darthand-hand-predictions", "version": 1,
     "frames": [{"index": frame index, "hands": [{"side": "right" | "left", "keypoints_3d": (21, 3) camera frame,
                 metres, "keypoints_2d": (21, 2) pixels (optional)}, ...]}, ...]}

keypoints in the ground truth's keypoint order (its labels' keypoint_names: openpose by default). The ground truth
is a darthand dataset folder; a dataset folder is also read as predictions (its labels' hands). Figures:

- per side: FreiHAND's keypoint figures (dataset/metrics.evaluate) over every hand of that side the predictions
  name, InterHand's root-relative MPJPE (each hand's wrist at the origin), and the mean 2-D error (pixels) where
  the prediction has 2-D keypoints;
- root-relative MPJPE of the hands of single-hand frames and of interacting frames (InterHand's two figures);
- MRRPE (InterHand2.6M's mean relative-root position error) over interacting frames (both hands in the ground
  truth and the prediction): root = the wrist, |(R_pred - L_pred) - (R_gt - L_gt)|, mm.

A ground-truth hand the predictions leave out is counted ('missing'), not scored.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from darthand.dataset.frames import frame_names
from darthand.dataset.hands import hand_type, hands_of
from darthand.dataset.metrics import evaluate
from darthand.dataset.run import read_shard_records
from darthand.errors import InputError
from darthand.fileio import read_json, write_bytes
from darthand.schemas import check_schema

PREDICTIONS_FORMAT = "darthand-hand-predictions"
SCHEMA = "hand_predictions.schema.json"
SIDES = ("right", "left")


def is_hand_predictions(path) -> bool:
    """Whether `path` is a per-hand predictions file (module docstring)."""
    path = Path(path)
    if not (path.is_file() and path.suffix == ".json"):
        return False
    doc = read_json(path, "predictions file")
    return isinstance(doc, dict) and doc.get("format") == PREDICTIONS_FORMAT


def dataset_hands(folder) -> tuple[dict, list[str]]:
    """({frame index: (hand type, [{side, keypoints_3d, keypoints_2d}])}, keypoint names) of a dataset folder."""
    folder = Path(folder)
    frames = read_shard_records(folder)
    if not frames:
        raise InputError(f"{folder}: no rendered frames")
    out, names = {}, []
    for f in frames:
        labels = read_json(folder / frame_names(f["index"])["labels"], "labels")
        names = labels["keypoint_names"]
        out[int(f["index"])] = (hand_type(labels), [_hand(h) for h in hands_of(labels)])
    return out, names


def _hand(h: dict) -> dict:
    return {"side": h["side"], "keypoints_3d": np.asarray(h["keypoints_3d"], np.float64),
            "keypoints_2d": None if h.get("keypoints_2d") is None else np.asarray(h["keypoints_2d"], np.float64)}


def load_hand_predictions(path) -> dict:
    """{frame index: [{side, keypoints_3d (21, 3), keypoints_2d (21, 2) or None}]} of a predictions file or a
    dataset folder."""
    path = Path(path)
    if path.is_dir():
        return {i: hands for i, (_, hands) in dataset_hands(path)[0].items()}
    doc = read_json(path, "predictions file")
    check_schema(doc, SCHEMA, str(path))
    out: dict = {}
    for frame in doc["frames"]:
        if int(frame["index"]) in out:
            raise InputError(f"{path}: frame {frame['index']} is listed twice")
        sides = [h["side"] for h in frame["hands"]]
        if len(set(sides)) < len(sides):
            raise InputError(f"{path}: frame {frame['index']} has two {sides[0]} hands")
        out[int(frame["index"])] = [_hand(h) for h in frame["hands"]]
    return out


def mrrpe_mm(pred: dict, gt: dict, root: int) -> float:
    """InterHand2.6M's relative-root error of one frame (mm): pred and gt {side: (21, 3) keypoints}, root the wrist's
    index."""
    rel_pred = pred["right"][root] - pred["left"][root]
    rel_gt = gt["right"][root] - gt["left"][root]
    return float(1000 * np.linalg.norm(rel_pred - rel_gt))


def root_relative_mpjpe_mm(pred: np.ndarray, gt: np.ndarray, root: int) -> float:
    """InterHand2.6M's MPJPE (mm) of keypoints (N, 21, 3), metres: each hand moved so that its root (index `root`)
    is at the origin, then the mean Euclidean distance."""
    pred = pred - pred[:, root:root + 1]
    gt = gt - gt[:, root:root + 1]
    return float(1000 * np.linalg.norm(pred - gt, axis=-1).mean())


def matched_hands(truth: dict, predicted: dict, root: int) -> tuple[list, int, list]:
    """([(side, 'single' | 'interacting', predicted hand, true hand)], hands not predicted, [MRRPE (mm) per
    interacting frame with both hands predicted])."""
    pairs, missing, mrrpe = [], 0, []
    for index, (kind, gt_hands) in sorted(truth.items()):
        mine = {h["side"]: h for h in predicted.get(index, [])}
        for h in gt_hands:
            if h["side"] in mine:
                pairs.append((h["side"], "interacting" if kind == "interacting" else "single", mine[h["side"]], h))
            else:
                missing += 1
        if kind == "interacting" and all(s in mine for s in SIDES):
            mrrpe.append(mrrpe_mm({s: mine[s]["keypoints_3d"] for s in SIDES},
                                  {h["side"]: h["keypoints_3d"] for h in gt_hands}, root))
    return pairs, missing, mrrpe


def side_figures(pairs: list, root: int) -> dict:
    """FreiHAND's keypoint figures of matched hands (matched_hands' pairs), the root-relative MPJPE, and the mean
    2-D error (pixels) where both have 2-D keypoints."""
    pred = np.stack([p["keypoints_3d"] for _, _, p, _ in pairs])
    gt = np.stack([g["keypoints_3d"] for _, _, _, g in pairs])
    figures = evaluate(pred, gt)
    figures["keypoints"]["root_relative_mpjpe_mm"] = round(root_relative_mpjpe_mm(pred, gt, root), 4)
    px = [np.linalg.norm(p["keypoints_2d"] - g["keypoints_2d"], axis=-1).mean() for _, _, p, g in pairs
          if p["keypoints_2d"] is not None and g["keypoints_2d"] is not None]
    if px:
        figures["keypoints"]["mean_2d_px"] = round(float(np.mean(px)), 4)
    return figures


def evaluate_hands(pred, gt) -> dict:
    """The per-side figures, the root-relative MPJPE of single and interacting frames' hands, and MRRPE of
    predictions `pred` (a predictions file or dataset folder) against the dataset folder `gt` (module docstring)."""
    if not (Path(gt).is_dir() and (Path(gt) / "dataset.json").is_file()):
        raise InputError(f"{gt}: per-hand predictions are evaluated against a darthand dataset folder")
    truth, names = dataset_hands(gt)
    predicted = load_hand_predictions(pred)
    unknown = sorted(set(predicted) - set(truth))
    if unknown:
        raise InputError(f"{pred}: frame {unknown[0]} is not in the ground truth {gt}")
    root = names.index("wrist")
    pairs, missing, mrrpe = matched_hands(truth, predicted, root)
    result: dict = {"pred": str(pred), "gt": str(gt), "samples": len(pairs), "missing_hands": missing,
                    "per_side": {}, "root_relative_mpjpe_mm": {}}
    for side in SIDES:
        some = [pair for pair in pairs if pair[0] == side]
        if some:
            result["per_side"][side] = side_figures(some, root)
    for kind in ("single", "interacting"):
        some = [pair for pair in pairs if pair[1] == kind]
        if some:
            result["root_relative_mpjpe_mm"][kind] = round(root_relative_mpjpe_mm(
                np.stack([p["keypoints_3d"] for _, _, p, _ in some]),
                np.stack([g["keypoints_3d"] for _, _, _, g in some]), root), 4)
    result["mrrpe"] = {"frames": len(mrrpe), "mm": round(float(np.mean(mrrpe)), 4) if mrrpe else None}
    return result


def hands_markdown(result: dict) -> str:
    """The figures of evaluate_hands as a markdown table."""
    lines = [f"# darthand eval: {result['samples']} hands ({result['missing_hands']} not predicted)", "",
             "| figure | value |", "|---|---|"]
    for side, figures in result["per_side"].items():
        for key, value in figures["keypoints"].items():
            lines.append(f"| {side} {key} | {value} |")
    for kind, value in result["root_relative_mpjpe_mm"].items():
        lines.append(f"| root-relative MPJPE mm, {kind} frames' hands | {value} |")
    lines.append(f"| MRRPE mm ({result['mrrpe']['frames']} interacting frames) | {result['mrrpe']['mm']} |")
    return "\n".join(lines) + "\n"


def write_hand_predictions(path, frames: dict) -> None:
    """Write a predictions file: frames {index: [{side, keypoints_3d (21, 3), keypoints_2d (21, 2) optional}]}."""
    doc = {"format": PREDICTIONS_FORMAT, "version": 1, "frames": [
        {"index": int(i), "hands": [{"side": h["side"], "keypoints_3d": np.asarray(h["keypoints_3d"]).tolist(),
                                     **({} if h.get("keypoints_2d") is None else
                                        {"keypoints_2d": np.asarray(h["keypoints_2d"]).tolist()})}
                                    for h in hands]} for i, hands in sorted(frames.items())]}
    write_bytes(path, json.dumps(doc).encode())
