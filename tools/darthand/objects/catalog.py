"""The object catalogue spec as data: read and check assets_src/objects/catalog.json, and resolve an item's
parameters.

An item's parameters are its kind's defaults overridden by its own keys. A number is used as it is, a pair
[lo, hi] is drawn uniformly, a list of lists is a choice (colours, linear RGB); every draw comes from
`item_rng(seed, id)`, so an item depends only on the catalogue seed and its id. `<name>_mm` becomes `<name>` in
metres.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import read_json
from darthand.schemas import check_schema, check_unique_ids

REPO_ROOT = Path(__file__).resolve().parents[3]
DEFAULT_SPEC = REPO_ROOT / "assets_src" / "objects" / "catalog.json"
CATEGORIES = ("mug", "bottle", "phone", "pen", "box", "ball", "tool", "card")
# Keys of an item that describe it rather than parametrise its generator.
ITEM_KEYS = ("id", "category", "kind", "name", "grasps", "source", "licence", "licence_file", "mesh", "texture",
             "repair")


def load_spec(path: str | Path = DEFAULT_SPEC) -> dict:
    """The parsed, schema-checked catalogue spec; InputError names the file and the offending field."""
    path = Path(path)
    spec = read_json(path, "object catalogue spec")
    check_spec(spec, str(path))
    return spec


def check_spec(spec: dict, source: str = "catalogue spec") -> None:
    """Schema errors and repeated ids raise InputError('<source>: field <path> ...')."""
    check_schema(spec, "object_catalog_spec.schema.json", source)
    check_unique_ids(spec["items"], source)


def select(spec: dict, ids=None) -> list[dict]:
    """The spec's items in order, only `ids` when given (InputError naming the first unknown id)."""
    items = spec["items"]
    if ids:
        known = {it["id"] for it in items}
        unknown = [i for i in ids if i not in known]
        if unknown:
            raise InputError(f"--ids: unknown object id {unknown[0]!r} (the catalogue has {len(known)} ids)")
        items = [it for it in items if it["id"] in set(ids)]
    return list(items)


def item_rng(seed: int, item_id: str) -> np.random.Generator:
    """The item's own generator, seeded from (catalogue seed, sha256 of the id)."""
    h = int.from_bytes(hashlib.sha256(item_id.encode()).digest()[:8], "little")
    return np.random.default_rng([int(seed), h])


def resolve(spec: dict, item: dict) -> dict:
    """The item's generator parameters: its kind's defaults under its own keys, ranges and choices drawn from the
    item's generator (in sorted key order, so adding a key to one item never shifts another's draws), millimetres
    converted to metres."""
    merged = {**spec.get("defaults", {}).get(item["kind"], {}), **item}
    rng = item_rng(spec["seed"], item["id"])
    out = {}
    for key in sorted(merged):
        if key in ITEM_KEYS:
            continue
        value = draw(merged[key], rng)
        if key.endswith("_mm"):
            out[key[:-3]] = float(value) / 1000.0
        else:
            out[key] = value
    return out


def draw(value, rng: np.random.Generator):
    """A number as it is; [lo, hi] drawn uniformly; a list of lists one of them (a list of floats)."""
    if isinstance(value, list) and value and isinstance(value[0], list):
        return [float(c) for c in value[int(rng.integers(len(value)))]]
    if isinstance(value, list) and len(value) == 2 and all(isinstance(v, (int, float)) for v in value):
        return float(rng.uniform(value[0], value[1]))
    return value


def grasps_for(spec: dict, item: dict) -> list[str]:
    """The grasp types an item suits: its own list, else its category's."""
    return list(item.get("grasps", spec.get("grasps", {}).get(item["category"], [])))
