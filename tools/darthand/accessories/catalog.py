"""The accessory catalogue as data: read and check assets_src/accessories/catalog.json, expand it into entries.

An entry is the item's keys over its type's defaults, with every `<name>_mm` length converted to metres as `<name>`.
Randomness for an item comes from `item_rng(seed, id)`, so an item's output depends only on the catalogue seed and
its id -- not on which other items are built, or in which order.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import read_json
from darthand.schemas import check_schema, check_unique_ids

REPO_ROOT = Path(__file__).resolve().parents[3]
DEFAULT_SPEC = REPO_ROOT / "assets_src" / "accessories" / "catalog.json"
TYPES = ("ring", "watch", "bracelet", "glove")


def load_spec(path: str | Path = DEFAULT_SPEC) -> dict:
    """The parsed, schema-checked catalogue spec; InputError names the file and the offending field."""
    path = Path(path)
    spec = read_json(path, "accessory catalogue")
    check_spec(spec, str(path))
    return spec


def check_spec(spec: dict, source: str = "catalogue") -> None:
    """Schema errors and duplicate ids raise InputError('<source>: field <path> ...')."""
    check_schema(spec, "accessory_catalog_spec.schema.json", source)
    check_unique_ids(spec["items"], source)


def entries(spec: dict, ids=None, types=None) -> list[dict]:
    """Expanded entries (metres) in catalogue order, optionally only the given ids and/or types."""
    items = spec["items"]
    if ids:
        known = {it["id"] for it in items}
        unknown = [i for i in ids if i not in known]
        if unknown:
            raise InputError(f"--ids: unknown accessory id {unknown[0]!r} (the catalogue has {len(known)} ids)")
        items = [it for it in items if it["id"] in set(ids)]
    if types:
        bad = [t for t in types if t not in TYPES]
        if bad:
            raise InputError(f"--type: {bad[0]!r} is not one of {', '.join(TYPES)}")
        items = [it for it in items if it["type"] in set(types)]
    defaults = spec.get("defaults", {})
    return [to_metres({**defaults.get(it["type"], {}), **it}) for it in items]


def to_metres(entry: dict) -> dict:
    """Keys ending in _mm become metres without the suffix; other keys unchanged."""
    out = {}
    for k, v in entry.items():
        if k.endswith("_mm"):
            out[k[:-3]] = float(v) / 1000.0
        else:
            out[k] = v
    return out


def item_rng(seed: int, item_id: str) -> np.random.Generator:
    """The item's own generator, seeded from (catalogue seed, sha256 of the id)."""
    h = int.from_bytes(hashlib.sha256(item_id.encode()).digest()[:8], "little")
    return np.random.default_rng([int(seed), h])


def check_catalog(catalog: dict, source: str = "catalog.json") -> None:
    """Validate a built catalogue against schemas/accessory_catalog.schema.json (InputError on failure)."""
    check_schema(catalog, "accessory_catalog.schema.json", source)
