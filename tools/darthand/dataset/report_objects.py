"""The dataset report's figures of object frames (frames of a hand holding an object, dataset/objects.py): how many,
per object category and per grasp type, from the frames' shard-record summaries (dataset/frames.summary); frames of
two hands on one object (interaction held or handover, dataset/object_pairs.py) also per type and category."""

from __future__ import annotations

from darthand.dataset.interaction_shares import OBJECT_TYPES


def object_counts(frames: list[dict]) -> dict:
    """{'frames', 'category': {name: count}, 'grasp_type': {name: count}} of the summaries' held objects, and
    'two_hands': {type: {category: frames}} when frames hold one object in both hands; {} for a dataset without
    object frames."""
    held = [o for f in frames for o in f.get("objects") or ()]
    if not held:
        return {}
    out: dict = {"frames": sum(1 for f in frames if f.get("objects"))}
    for key in ("category", "grasp_type"):
        table: dict = {}
        for o in held:
            table[str(o.get(key))] = table.get(str(o.get(key)), 0) + 1
        out[key] = dict(sorted(table.items()))
    both = two_hand_counts(frames)
    if both:
        out["two_hands"] = both
    return out


def two_hand_counts(frames: list[dict]) -> dict:
    """{interaction type: {object category: frames}} of the frames of two hands on one object."""
    out: dict = {}
    for f in frames:
        if f.get("interaction") in OBJECT_TYPES:
            for o in f.get("objects") or ():
                table = out.setdefault(f["interaction"], {})
                table[str(o.get("category"))] = table.get(str(o.get("category")), 0) + 1
    return {kind: dict(sorted(table.items())) for kind, table in sorted(out.items())}
