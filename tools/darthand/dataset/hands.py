"""The hands of a frame's labels, one form for the writers, the report and eval: a two-hand frame's labels hold
them in `hands` (issue 29's contract: per hand side, keypoints, visibility, mano, mesh, ...); a one-hand frame's
labels are themselves the hand (the same per-hand keys at top level)."""

from __future__ import annotations

import numpy as np

from darthand.model.mirror import mirror_pose

HAND_TYPES = ("right", "left", "interacting")


def hands_of(labels: dict) -> list[dict]:
    """The hands of a frame's labels, in the job's bodies order: labels["hands"] for a multi-hand frame, [labels]
    for a one-hand frame."""
    if "hands" in labels:
        return list(labels["hands"])
    return [labels]


def is_multi_hand(labels: dict) -> bool:
    """Whether a frame's labels hold more than one hand."""
    return len(hands_of(labels)) > 1


def hand_type(labels: dict) -> str:
    """InterHand2.6M's hand type of a frame: 'interacting' (both hands in the scene), else its one hand's side."""
    hands = hands_of(labels)
    return labels.get("hand_type") or ("interacting" if len(hands) > 1 else hands[0]["side"])


def interaction_type(labels: dict) -> str:
    """The frame's interaction type (the job's interaction record's), 'none' for a one-hand frame."""
    return str((labels.get("interaction") or {}).get("type", "none"))


def hands_mean(models: dict, side: str) -> np.ndarray:
    """(45,) a side's mean hand (dataset.json 'models'): its own, else the other side's mirrored, else zeros."""
    other = "left" if side == "right" else "right"
    if "hands_mean" in models.get(side, {}):
        return np.asarray(models[side]["hands_mean"], np.float64)
    if "hands_mean" in models.get(other, {}):
        return mirror_pose(np.asarray(models[other]["hands_mean"], np.float64))
    return np.zeros(45)
