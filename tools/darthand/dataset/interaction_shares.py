"""The interaction types of two-hand frames and the shares a plan draws them by (dataset/interactions.py draws
them; this module is apart so that a plan's options are checked without loading the geometry)."""

from __future__ import annotations

import math

from darthand.errors import InputError

TYPES = ("apart", "touching", "clasped", "interlaced", "holding", "overlapping", "mirrored")
# Two hands and one object (dataset/object_pairs.py): asked for by name only, never in the equal default shares,
# and in a plan's shares only when named (so plans without them keep their documents and draws).
OBJECT_TYPES = ("held", "handover")
# What the two-hand fit moves (model/hand_pair.resolve): the left hand rigidly, or that and the digits near the other.
FITS = ("digits", "rigid")


def parse_shares(text) -> dict:
    """Shares per type from 'apart=0.2,clasped=0.8' or a dict; None: equal shares. InputError naming the fault."""
    if text is None:
        return {t: 1.0 / len(TYPES) for t in TYPES}
    if isinstance(text, str):
        pairs = {}
        for item in (t for t in text.replace(" ", "").split(",") if t):
            name, eq, value = item.partition("=")
            if not eq:
                raise InputError(f"interactions: {item!r} is not TYPE=SHARE")
            try:
                pairs[name] = float(value)
            except ValueError:
                raise InputError(f"interactions: share {value!r} of {name!r} is not a number") from None
        text = pairs
    return check_shares(text)


def check_shares(shares: dict) -> dict:
    """{type: share} checked: known types, shares within [0, 1] summing to 1 (TYPES left out get 0; OBJECT_TYPES are
    kept only when named)."""
    if not isinstance(shares, dict) or not shares:
        raise InputError("interactions: give shares per type, e.g. apart=0.5,clasped=0.5")
    out = {t: 0.0 for t in TYPES}
    for name, value in shares.items():
        if name not in TYPES + OBJECT_TYPES:
            raise InputError(f"interactions: {name!r} is not an interaction type ({', '.join(TYPES + OBJECT_TYPES)})")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                math.isfinite(value) and 0 <= value <= 1):
            raise InputError(f"interactions: share {value!r} of {name!r} is outside 0..1")
        out[name] = float(value)
    total = sum(out.values())
    if abs(total - 1) > 1e-6:
        raise InputError(f"interactions: shares sum to {total:g}, not 1")
    return out


def choose_type(u: float, shares: dict) -> str:
    """The type whose cumulative share interval holds the uniform u."""
    edge = 0.0
    for name in TYPES + OBJECT_TYPES:
        edge += shares.get(name, 0.0)
        if u < edge:
            return name
    return next(t for t in reversed(TYPES + OBJECT_TYPES) if shares.get(t, 0.0) > 0)


def object_share(shares: dict) -> float:
    """The share of the types with an object (OBJECT_TYPES) among checked `shares`."""
    return sum(shares.get(t, 0.0) for t in OBJECT_TYPES)
