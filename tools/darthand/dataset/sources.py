"""The frame sources of a dataset, one per hand side: what `render.api.open_source` opens, for the side asked.

A dataset of PACKAGE renders its side and, for the other side, its twin: a USD package's sibling folder
(build/usd/left beside build/usd/right), a build model's sibling npz (build/model/left.npz), or else the model
mirrored in memory (model.mirror.mirror_model; the accessory catalogue is mirrored by its loader). A `SourceSpec`
is plain data, so worker processes (and other machines) open the same sources.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from darthand.errors import InputError
from darthand.model.load import load_model
from darthand.model.mirror import mirror_model
from darthand.render.api import open_source
from darthand.render.assets import HandAssets, default_catalogues

SIDES = ("right", "left")


@dataclass(frozen=True)
class SourceSpec:
    """How to open one side's source: package (a path or name for api.open_source), catalogues, the USD path's
    model, and `mirror` (load the model and mirror it)."""

    package: str
    textures: str | None = None
    accessories: str | None = None
    model: str | None = None
    mirror: bool = False

    def open(self):
        if not self.mirror:
            return _worn_rings(open_source(self.package, textures=self.textures, accessories=self.accessories,
                                          model=self.model))

        path = Path("build") / "model" / f"{self.package}.npz" if self.package in SIDES else Path(self.package)
        tex, acc = self.textures, self.accessories
        if path.suffix == ".npz" and path.is_file():
            found = default_catalogues(path)
            tex, acc = tex or found[0], acc or found[1]
        twin = HandAssets.load(mirror_model(load_model(str(path))), tex or None, acc or None)
        twin.source = f"{self.package} (mirrored)"
        return _worn_rings(twin)


def _worn_rings(source):
    """The source with rings worn per pose (accessories/wear: slid along the bone, digits turned aside where the
    ring needs room; the frame's labels follow the pose it shows) where it poses the hand itself (a model source);
    a USD package poses its rings rigidly, as every package does."""
    source.worn_rings = True
    return source


def parse_sides(text) -> tuple[str, ...]:
    """('right',), ('left',) or ('right', 'left') from 'right', 'left', 'both' or a comma list."""
    items = [text] if isinstance(text, str) else list(text)
    names = []
    for item in items:
        for name in str(item).replace(" ", ",").split(","):
            if name == "both":
                names += list(SIDES)
            elif name in SIDES:
                names.append(name)
            elif name:
                raise InputError(f"sides: {name!r} is not right, left or both")
    names = [s for s in SIDES if s in names]
    if not names:
        raise InputError("sides: none given")
    return tuple(names)


def source_specs(package, sides, *, textures=None, accessories=None, model=None, opened=None) -> dict:
    """{side: SourceSpec} for the sides asked. opened: PACKAGE already opened (its side is read from it)."""
    package = str(package)
    first = opened if opened is not None else open_source(package, textures=textures, accessories=accessories,
                                                          model=model)
    own = first.side
    specs = {}
    for side in sides:
        if side == own:
            specs[side] = SourceSpec(package, textures, accessories, model)
            continue
        twin = _twin_path(package, own, side)
        if first.pose_model() is None:                                                  # a USD package
            if twin is None or not (twin / "asset.json").is_file():
                raise InputError(f"sides: {package} is a {own} USD package and {twin or 'its ' + side + ' twin'} "
                                 f"is not a built package (build it, or render --sides {own})")
            specs[side] = SourceSpec(str(twin), None, None, None)
        elif twin is not None and twin.is_file():
            specs[side] = SourceSpec(str(twin), textures, accessories, None)
        else:
            specs[side] = SourceSpec(package, textures, accessories, model, mirror=True)
    return specs


def _twin_path(package: str, own: str, side: str) -> Path | None:
    """The other side's file or folder named like PACKAGE: 'left' for 'right', build/model/left.npz for
    build/model/right.npz, build/usd/left for build/usd/right; None when PACKAGE is not named by its side."""
    if package in SIDES:
        return Path("build") / "model" / f"{side}.npz"
    path = Path(package)
    if path.suffix == ".npz" and path.stem == own:
        return path.with_name(f"{side}.npz")
    if path.is_dir() and path.name == own:
        return path.with_name(side)
    if path.suffix in (".usda", ".usd", ".usdc") and path.parent.name == own:
        return path.parent.with_name(side)
    return None
