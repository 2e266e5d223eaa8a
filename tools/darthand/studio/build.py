"""What a build folder offers the studio page, and the one place a request's ids are checked.

A side (right, left) is offered when the build has its model (build/model/<side>.npz) and its glTF variants package
(build/gltf/<side>/<side>.gltf, `make assets`). Ids the page may name are the render source's (render/assets.py:
the texture and accessory catalogues next to the model) that the glTF package also carries (its
KHR_materials_variants); the package's files are those its .gltf lists (buffers and images), so no request names
a path.
"""

from __future__ import annotations

from typing import Any

import json
import threading
from dataclasses import dataclass, field
from pathlib import Path

from darthand.dataset.backgrounds import BUILTIN_COUNT, list_images
from darthand.dataset.lighting import PALETTE, PALETTE_K
from darthand.dataset.plan import texture_tags
from darthand.errors import InputError
from darthand.model.preview import VIEWS
from darthand.render.api import open_source
from darthand.studio.environments import EnvironmentSet
from darthand.studio.objects import StudioObjects, find_catalogs
from darthand.studio.request_error import RequestError

SIDES = ("right", "left")


@dataclass
class SideAssets:
    """One side of the build: its glTF package (`gltf` the .gltf path, `files` the relative URIs it references),
    the render source (render/assets.HandAssets: model, catalogues) and the texture variants both carry; `lock`
    guards the side's lazily made `renderer` (render/api.Renderer) and `preview` maps (thumbnails)."""

    side: str
    gltf: Path
    files: frozenset
    source: Any                   # render/assets.HandAssets
    variants: list
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    renderer: object = field(default=None, repr=False)
    preview: object = field(default=None, repr=False)

    @property
    def model(self):
        return self.source.pose_model()


class StudioBuild:
    """A build folder opened for the studio: its sides (SideAssets), optional background images, the environment
    maps (the built-in set and an optional folder's), the held objects and their grasps (studio/objects.py: the
    build's objects/ and grasps/, or the catalogues named; None when there are none)."""

    def __init__(self, root, backgrounds=None, environments=None, objects=None, grasps=None):
        self.root = Path(root).resolve()
        if not self.root.is_dir():
            raise InputError(f"{root}: not a build folder (run `make assets`)")
        self.sides = {side: _open_side(self.root, side) for side in SIDES if _has_side(self.root, side)}
        if not self.sides:
            raise InputError(f"{self.root}: no glTF package with its model (gltf/<side>/<side>.gltf and "
                             "model/<side>.npz; run `make assets`)")
        self.background_folder, self.background_files = None, []
        if backgrounds is not None:
            self.background_folder = Path(backgrounds).resolve()
            self.background_files = list_images(self.background_folder, max_files=10_000)
        self.environments = EnvironmentSet(environments)
        catalogs = find_catalogs(self.root, objects, grasps)
        self.objects = None if catalogs is None else StudioObjects(
            *catalogs, {name: side.model for name, side in self.sides.items()})

    @property
    def out_dir(self) -> Path:
        """Where the studio writes: exports and its thumbnail cache (BUILD/studio)."""
        return self.root / "studio"

    # ---------------------------------------------------------------------------------------------- checks

    def side(self, name) -> SideAssets:
        if name not in self.sides:
            raise RequestError(404, f"side {name!r} is not in the build (sides: {', '.join(self.sides)})")
        return self.sides[name]

    def texture(self, side: SideAssets, texture_id) -> str:
        if texture_id not in side.variants:
            raise RequestError(404, f"texture {texture_id!r} is not a texture of the {side.side} package")
        return texture_id

    def accessory(self, side: SideAssets, accessory_id) -> str:
        if accessory_id != "none" and accessory_id not in side.source.accessories:
            raise RequestError(404, f"accessory {accessory_id!r} is not in the accessory catalogue")
        return accessory_id

    def package_file(self, side: SideAssets, name: str) -> Path:
        """The package file with relative URI `name` (only those the .gltf lists, and the .gltf itself)."""
        if name == side.gltf.name:
            return side.gltf
        if name not in side.files:
            raise RequestError(404, f"{name!r} is not a file of the {side.side} glTF package")
        return side.gltf.parent / name

    def background_file(self, index) -> Path:
        if not isinstance(index, int) or not 0 <= index < len(self.background_files):
            raise RequestError(404, f"background image {index!r} is not one of the {len(self.background_files)} "
                                    "listed")
        return self.background_folder / self.background_files[index]

    # ---------------------------------------------------------------------------------------------- the page

    def catalogue(self) -> dict:
        """What the page lists: sides, textures (id, tone, category) and accessories (id, type) of the first side,
        gestures per side, light palette, named views, backgrounds, whether held objects are offered."""
        first = next(iter(self.sides.values()))
        return {
            "sides": list(self.sides),
            "textures": [{"id": t, **texture_tags(t)} for t in first.variants],
            "default_texture": first.variants[0] if first.variants else None,
            "accessories": [{"id": a.id, "type": a.kind or "accessory"} for a in first.source.accessories.values()],
            "palette": [{"name": n, "kelvin": PALETTE_K[n], "rgb": PALETTE[n]} for n in PALETTE],
            "views": list(VIEWS),
            "backgrounds": {"builtin": BUILTIN_COUNT, "images": self.background_files},
            "objects": self.objects is not None,
        }


def _has_side(root: Path, side: str) -> bool:
    return (root / "gltf" / side / f"{side}.gltf").is_file() and (root / "model" / f"{side}.npz").is_file()


def _open_side(root: Path, side: str) -> SideAssets:
    gltf = root / "gltf" / side / f"{side}.gltf"
    try:
        doc = json.loads(gltf.read_text())
    except (OSError, ValueError) as e:
        raise InputError(f"{gltf}: cannot read the glTF package ({e})") from None
    uris = [b.get("uri") for b in doc.get("buffers", [])] + [i.get("uri") for i in doc.get("images", [])]
    files = frozenset(u for u in uris if isinstance(u, str) and _plain_relative(u))
    source = open_source(root / "model" / f"{side}.npz")
    names = [v.get("name") for v in doc.get("extensions", {}).get("KHR_materials_variants", {}).get("variants", [])]
    if not names:                              # one texture: the package's material names it
        materials = doc.get("materials", [])
        names = [materials[0].get("extras", {}).get("darthand", {}).get("texture")] if materials else []
    variants = [n for n in names if n in source.textures]
    return SideAssets(side, gltf, files, source, variants)


def _plain_relative(uri: str) -> bool:
    """A URI that names a file inside the package's folder (no scheme, no absolute path, no '..')."""
    parts = uri.split("/")
    return ":" not in uri and not uri.startswith("/") and "\\" not in uri and all(p not in ("", ".", "..")
                                                                                  for p in parts)
