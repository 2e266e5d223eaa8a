"""Reading the textures stage's catalogue (build/textures/catalog.json): the skin texture variants other stages use
(export writes them into packages, the renderer shades with them). The textures stage owns how its catalogue is
read; other stages import from here.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from darthand.errors import InputError
from darthand.fileio import file_in
from darthand.schemas import read_catalog

# The hand's look without a texture (both package writers and the renderer): a mid skin tone, linear RGB, and its
# roughness (also that of a skin texture variant without a roughness map).
SKIN_COLOR = (0.56, 0.36, 0.27)
SKIN_ROUGHNESS = 0.5


@dataclass(frozen=True)
class TextureSet:
    """One skin texture variant: `id` (the variant name), an sRGB albedo PNG and an optional raw roughness PNG.
    tone_srgb: the colour of the back of the hand in the albedo (3 floats, sRGB): the catalogue's base tone plus the
    skin-tone offset baked into the image (a catalogue's entries have both), None for a set made without one."""

    id: str
    albedo: Path
    roughness: Path | None = None
    tone_srgb: tuple | None = None



def load_texture_catalog(path: str | Path) -> list[TextureSet]:
    """The skin texture variants of a textures-stage catalogue (build/textures/catalog.json, or its folder), the
    default variant first (the catalogue's 'default' when it names an entry, else its first entry), then the others
    in catalogue order.

    The file must validate against schemas/texture_catalog.schema.json (InputError naming the field otherwise).
    Each entry's files.albedo (sRGB PNG) and files.roughness (raw PNG or null) are relative to the catalogue.
    """
    path, data = read_catalog(path, "texture", "texture_catalog.schema.json")
    if not data["entries"]:
        raise InputError(f"{path}: field 'entries' is empty (build textures with the textures stage)")
    entries = sorted(data["entries"], key=lambda e: e["id"] != data.get("default"))     # stable: default first
    return [TextureSet(e["id"], file_in(path.parent, e["files"]["albedo"], "texture", must_exist=False),
                       file_in(path.parent, e["files"]["roughness"], "texture", must_exist=False)
                       if e["files"]["roughness"] else None, baked_tone(e))
            for e in entries]


def baked_tone(entry: dict) -> tuple:
    """(3,) sRGB the tone an entry's albedo shows on the back of the hand: its tone_srgb plus its offset (the
    textures stage adds it to every texel), clipped to [0, 1]. Over the 325 catalogue entries it is within -0.015
    of the back of the hand's median texel on average (at most 0.10 in a channel)."""
    return tuple(min(max(float(c) + float(entry["offset"]), 0.0), 1.0) for c in entry["tone_srgb"])


def select_textures(sets: list[TextureSet], ids) -> list[TextureSet]:
    """The sets with the given ids, in that order (InputError naming an unknown id)."""
    by_id = {t.id: t for t in sets}
    missing = [i for i in ids if i not in by_id]
    if missing:
        raise InputError(f"--texture: {missing[0]!r} is not in the texture catalogue")
    return [by_id[i] for i in ids]
