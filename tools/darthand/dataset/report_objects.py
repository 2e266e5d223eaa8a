"""The dataset report's figures of object frames (frames of a hand holding an object, dataset/objects.py): how many,
per object category and per grasp type, from the frames' shard-record summaries (dataset/frames.summary)."""

from __future__ import annotations


def object_counts(frames: list[dict]) -> dict:
    """{'frames', 'category': {name: count}, 'grasp_type': {name: count}} of the summaries' held objects; {} for a
    dataset without object frames."""
    held = [o for f in frames for o in f.get("objects") or ()]
    if not held:
        return {}
    out: dict = {"frames": sum(1 for f in frames if f.get("objects"))}
    for key in ("category", "grasp_type"):
        table: dict = {}
        for o in held:
            table[str(o.get(key))] = table.get(str(o.get(key)), 0) + 1
        out[key] = dict(sorted(table.items()))
    return out
