"""Pose-estimation metrics as FreiHAND's evaluation computes them, on numpy arrays (metres in, millimetres out).

- Procrustes alignment with scale (`align_similarity`): the similarity transform (rotation, isotropic scale,
  translation) that maps a prediction onto the ground truth in the least-squares sense (Umeyama 1991), with a proper
  rotation (det +1; FreiHAND's toolbox lets scipy's orthogonal_procrustes pick a reflection, which a hand
  prediction never needs).
- MPJPE / MPVPE: mean Euclidean distance over keypoints / vertices (per point, then over samples); PA-: after
  alignment of each sample (keypoints on keypoints, vertices on vertices).
- F-score at a threshold t: precision = share of predicted points within t of a ground-truth point, recall =
  share of ground-truth points within t of a predicted point, F = 2 P R / (P + R) (FreiHAND: on vertices, at 5 and
  15 mm).
- AUC: the area under the PCK curve (share of points within t, t in 100 steps over 0..50 mm), trapezoidal, divided
  by the range, per point and then averaged (FreiHAND's EvalUtil).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

AUC_RANGE_M = (0.0, 0.05)
AUC_STEPS = 100
F_THRESHOLDS_M = (0.005, 0.015)
_trapezoid = getattr(np, "trapezoid", None) or np.trapz  # type: ignore[attr-defined, unused-ignore]  # numpy < 2 calls it trapz


def align_similarity(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """(N, 3) `pred` mapped by the least-squares similarity transform onto `gt` (N, 3)."""
    p, g = np.asarray(pred, np.float64), np.asarray(gt, np.float64)
    mp, mg = p.mean(0), g.mean(0)
    pc, gc = p - mp, g - mg
    U, S, Vt = np.linalg.svd(gc.T @ pc)
    d = np.sign(np.linalg.det(U @ Vt)) or 1.0
    D = np.diag([1.0, 1.0, d])
    R = U @ D @ Vt
    var = (pc * pc).sum()
    scale = (S * np.diag(D)).sum() / var if var > 0 else 1.0
    return scale * pc @ R.T + mg


def point_errors(pred: np.ndarray, gt: np.ndarray, aligned: bool) -> np.ndarray:
    """(B, N) Euclidean distances (metres) of predicted points to their ground truth, per sample aligned or not."""
    pred, gt = np.asarray(pred, np.float64), np.asarray(gt, np.float64)
    if aligned:
        pred = np.stack([align_similarity(p, g) for p, g in zip(pred, gt)])
    return np.linalg.norm(pred - gt, axis=-1)


def auc_pck(errors: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(AUC, thresholds (T,) metres, PCK curve (T,)) of per-point errors (B, N): per point the share of samples within
    each threshold (<=), the area under it over the range, then the mean over points (FreiHAND's EvalUtil)."""
    thresholds = np.linspace(*AUC_RANGE_M, AUC_STEPS)
    per_point = (errors[None, :, :] <= thresholds[:, None, None]).mean(axis=1)      # (T, N)
    norm = _trapezoid(np.ones_like(thresholds), thresholds)
    auc = _trapezoid(per_point, thresholds, axis=0) / norm
    return float(auc.mean()), thresholds, per_point.mean(axis=1)


def f_score(pred: np.ndarray, gt: np.ndarray, threshold: float) -> float:
    """F-score of two point sets (N, 3), (M, 3) at `threshold` metres (strictly closer, as FreiHAND)."""
    d_pred = cKDTree(gt).query(pred)[0]        # each predicted point to the nearest ground-truth point
    d_gt = cKDTree(pred).query(gt)[0]
    precision, recall = float((d_pred < threshold).mean()), float((d_gt < threshold).mean())
    return 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0


def evaluate(pred_xyz, gt_xyz, pred_verts=None, gt_verts=None) -> dict:
    """FreiHAND's figures (millimetres; AUC and F-scores in 0..1) for keypoints (B, 21, 3) and optionally vertices
    (B, V, 3), metres."""
    out: dict = {"samples": int(len(gt_xyz))}
    for name, pred, gt in (("keypoints", pred_xyz, gt_xyz), ("vertices", pred_verts, gt_verts)):
        if pred is None or gt is None:
            continue
        raw, aligned = point_errors(pred, gt, False), point_errors(pred, gt, True)
        short = "mpjpe" if name == "keypoints" else "mpvpe"
        out[name] = {short + "_mm": round(1000 * float(raw.mean()), 4),
                     "pa_" + short + "_mm": round(1000 * float(aligned.mean()), 4),
                     "auc": round(auc_pck(raw)[0], 5), "pa_auc": round(auc_pck(aligned)[0], 5)}
        if name == "vertices":
            aligned_pred = [align_similarity(p, g) for p, g in zip(pred, gt)]
            for t in F_THRESHOLDS_M:
                mm = round(1000 * t)
                out[name][f"f@{mm}mm"] = round(float(np.mean([f_score(p, g, t) for p, g in zip(pred, gt)])), 5)
                out[name][f"pa_f@{mm}mm"] = round(float(np.mean([f_score(p, g, t)
                                                                  for p, g in zip(aligned_pred, gt)])), 5)
    return out
