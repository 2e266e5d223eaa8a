"""The two-hand part of `darthand dataset report` (issue 29), written only when a dataset holds two-hand frames (a
one-hand dataset's report is unchanged): counts per interaction type and hand type (report.json 'two_hands') and a
contact sheet of two-hand frames per interaction type (two_hands.png: a row per type, both hands' keypoints and
skeletons drawn in two colours, hollow markers where a keypoint is not visible)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darthand.dataset.frames import frame_names
from darthand.dataset.hands import hand_type, hands_of, interaction_type
from darthand.fileio import read_json
from darthand.render.image import read_png

HAND_COLOURS = ("#ff3030", "#30a0ff")           # hand 0, hand 1 (the job's bodies order: right first as planned)
PER_TYPE = 6                                    # frames per interaction type on the sheet


def two_hand_frames(root: Path, frames: list[dict]) -> tuple[dict, dict]:
    """(counts {'hand_type': {...}, 'interaction': {...}}, {interaction type: [frame index of two-hand frames]})
    over every frame's labels."""
    kinds: dict = {}
    types: dict = {}
    by_type: dict = {}
    for f in frames:
        labels = read_json(root / frame_names(f["index"])["labels"], "labels")
        kind = hand_type(labels)
        kinds[kind] = kinds.get(kind, 0) + 1
        if len(hands_of(labels)) > 1:
            t = interaction_type(labels)
            types[t] = types.get(t, 0) + 1
            by_type.setdefault(t, []).append(int(f["index"]))
    return {"hand_type": dict(sorted(kinds.items())), "interaction": dict(sorted(types.items()))}, by_type


def write_two_hand_sheet(root: Path, by_type: dict, page: Path, bones: list) -> None:
    """two_hands.png: up to PER_TYPE two-hand frames of each interaction type, a row per type."""
    import matplotlib.pyplot as plt         # imported when a report is drawn (start-up time)

    rows = sorted(by_type)
    cols = max(min(PER_TYPE, len(v)) for v in by_type.values())
    fig, axes = plt.subplots(len(rows), cols, figsize=(2.6 * cols, 2.8 * len(rows)), dpi=90, squeeze=False)
    for r, t in enumerate(rows):
        for c in range(cols):
            ax = axes[r][c]
            ax.axis("off")
            if c < len(by_type[t]):
                _tile(ax, root, by_type[t][c], bones)
        axes[r][0].set_title(f"{t} ({len(by_type[t])})", loc="left", fontsize=10)
    fig.suptitle("two-hand frames per interaction type (red: hand 0, blue: hand 1; hollow: not visible)")
    fig.savefig(page, bbox_inches="tight")
    plt.close(fig)


def _tile(ax, root: Path, index: int, bones: list) -> None:
    names = frame_names(index)
    image = read_png(root / names["image"]).astype(np.float32) / 255
    rgb = image[..., :3] * image[..., 3:4] + 0.5 * (1 - image[..., 3:4]) if image.shape[2] == 4 else image
    labels = read_json(root / names["labels"], "labels")
    ax.imshow(rgb)
    for b, hand in enumerate(hands_of(labels)):
        uv = np.asarray(hand["keypoints_2d"])
        colour = HAND_COLOURS[b % len(HAND_COLOURS)]
        for i, j in bones:
            ax.plot(uv[[i, j], 0], uv[[i, j], 1], color=colour, lw=1.0, alpha=0.9)
        for k, (x, y) in enumerate(uv):
            ax.plot(x, y, "o", ms=2.5, mfc=colour if hand["visibility"][k] else "none", mec=colour, mew=0.8)
    ax.set_xlim(0, labels["image_size"][0])
    ax.set_ylim(labels["image_size"][1], 0)
    ax.text(3, 12, f"#{index} {labels.get('split', '')}", color="white", fontsize=7,
            bbox={"facecolor": "black", "alpha": 0.5, "pad": 1, "lw": 0})
