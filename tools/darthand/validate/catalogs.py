"""The catalogue ids a package's variant ids are checked against.

A package written by the pipeline sits in build/usd/<side>/ or build/gltf/; its catalogues are the built ones,
build/textures/catalog.json and build/accessories/[<side>/]catalog.json, found by looking for `textures/` and
`accessories/` in the package's folder and up to three folders above it. Without a built catalogue the ids are
those of the committed catalogue specs (assets_src/textures/, assets_src/accessories/), expanded by their own
catalogue modules. `plain` (the USD writer's untextured variant) and `none` (no accessory) are always known.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from darthand.errors import DarthandError
from darthand.fileio import read_json

ALWAYS_TEXTURES = {"plain"}
ALWAYS_ACCESSORIES = {"none"}
SEARCH_DEPTH = 3


def known_texture_ids(package_root: Path) -> tuple[frozenset[str], str]:
    """(ids, where they came from)."""
    found = _nearby(package_root, ("textures/catalog.json",))
    if found is not None:
        ids = _catalog_ids(str(found), ("entries", "textures", "variants", "items"))
        if ids:
            return ids | ALWAYS_TEXTURES, str(found)
    return _spec_texture_ids() | ALWAYS_TEXTURES, "the texture catalogue spec (assets_src/textures/catalog.json)"


def known_accessory_ids(package_root: Path, side: str | None = None) -> tuple[frozenset[str], str]:
    names = ([f"accessories/{side}/catalog.json"] if side else []) + ["accessories/catalog.json"]
    found = _nearby(package_root, tuple(names))
    if found is not None:
        ids = _catalog_ids(str(found), ("accessories", "entries", "items"))
        if ids:
            return ids | ALWAYS_ACCESSORIES, str(found)
    return _spec_accessory_ids() | ALWAYS_ACCESSORIES, \
        "the accessory catalogue spec (assets_src/accessories/catalog.json)"


def _nearby(root: Path, names: tuple[str, ...]) -> Path | None:
    folder = root if root.is_dir() else root.parent
    for base in [folder, *list(folder.parents)[:SEARCH_DEPTH]]:
        for name in names:
            if (base / name).is_file():
                return base / name
    return None


@lru_cache(maxsize=16)
def _catalog_ids(path: str, keys: tuple[str, ...]) -> frozenset:
    try:
        data = read_json(path, "catalogue")
    except DarthandError:          # not a readable catalogue: no ids from it (the texture rules say what is unknown)
        return frozenset()
    entries = data if isinstance(data, list) else next(
        (data[k] for k in keys if isinstance(data, dict) and isinstance(data.get(k), list)), [])
    return frozenset(str(e["id"]) for e in entries if isinstance(e, dict) and "id" in e)


@lru_cache(maxsize=1)
def _spec_texture_ids() -> frozenset:
    # lazy: the texture catalogue loads the model stack (0.13 s in the CLI, 1.5 s alone), only for recorded ids
    from darthand.textures.catalog import expand_catalog, load_spec

    return frozenset(e.id for e in expand_catalog(load_spec()))


@lru_cache(maxsize=1)
def _spec_accessory_ids() -> frozenset:
    from darthand.accessories.catalog import load_spec  # lazy: as above, only for packages that record accessory ids

    return frozenset(item["id"] for item in load_spec()["items"])
