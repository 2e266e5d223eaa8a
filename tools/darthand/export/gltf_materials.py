"""Skin materials for glTF: PBR metallic-roughness with the albedo texture, and texture variants via
KHR_materials_variants.

Each skin texture variant is one material (base colour = the albedo PNG, sRGB; metallic-roughness = the raw
roughness PNG if there is one, read through its G channel, with metallicFactor 0 so its B channel does not matter).
The primitive's own material is the default variant's; KHR_materials_variants lists every variant and maps it to
its material, which three.js and Blender both switch between.

Images are either embedded (PNG bytes in the binary buffer, for .glb) or referenced by a relative URI (for the
.gltf variants package, where hundreds of textures would otherwise make one file of gigabytes that loaders decode
whole; with URIs a loader fetches only the variant it shows).
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import quote

import pygltflib as gl

from darthand.export.texture_files import place_texture, texture_bytes
from darthand.textures.loader import SKIN_COLOR, SKIN_ROUGHNESS, TextureSet
from darthand.export.gltf_document import GltfDocument

VARIANTS_EXT = "KHR_materials_variants"


# ------------------------------------------------------------------------------------------------ materials


class MaterialBuilder:
    """Creates textures and skin materials in a document; images embedded or written next to a .gltf.

    package_dir: None embeds images in the buffer; otherwise images are placed under package_dir/textures/ and
    referenced by relative URIs. texture_size: downsize images to this many pixels (longer side).
    """

    def __init__(self, doc: GltfDocument, package_dir: Path | None = None, texture_size: int | None = None):
        self.doc = doc
        self.package_dir = package_dir
        self.texture_size = texture_size
        self._sampler: int | None = None
        self.image_files: list[Path] = []

    def texture(self, name: str, src: Path, color: bool) -> int:
        """A texture for the PNG at `src`, named `name` (also its file name in a package)."""
        if self.package_dir is None:
            image = self.doc.image(name, png=texture_bytes(src, self.texture_size, color))
        else:
            rel = Path("textures") / f"{name}.png"
            place_texture(src, self.package_dir / rel, self.texture_size, color)
            self.image_files.append(self.package_dir / rel)
            image = self.doc.image(name, uri=quote(rel.as_posix()))   # URIs are percent-encoded
        return self.doc.add("textures", gl.Texture(name=name, source=image, sampler=self.sampler()))

    def sampler(self) -> int:
        """One shared sampler: trilinear filtering, repeat wrapping."""
        if self._sampler is None:
            self._sampler = self.doc.add("samplers", gl.Sampler(magFilter=gl.LINEAR,
                                                                minFilter=gl.LINEAR_MIPMAP_LINEAR))
        return self._sampler

    def skin_material(self, textures: TextureSet | None, name: str = "skin") -> int:
        """A PBR skin material, textured by `textures` (or a plain skin tone without)."""
        pbr = gl.PbrMetallicRoughness(metallicFactor=0.0)
        if textures is None:
            pbr.baseColorFactor = [*SKIN_COLOR, 1.0]
            pbr.roughnessFactor = SKIN_ROUGHNESS
        else:
            pbr.baseColorTexture = gl.TextureInfo(index=self.texture(f"{textures.id}_albedo", textures.albedo, True))
            if textures.roughness is not None:
                pbr.metallicRoughnessTexture = gl.TextureInfo(
                    index=self.texture(f"{textures.id}_roughness", textures.roughness, False))
            else:
                pbr.roughnessFactor = SKIN_ROUGHNESS
        extras = {"darthand": {"texture": textures.id}} if textures is not None else {}
        return self.doc.add("materials", gl.Material(name=name, pbrMetallicRoughness=pbr, extras=extras))

    def pbr_material(self, name: str, base_color=(1.0, 1.0, 1.0, 1.0), metallic: float = 0.0,
                     roughness: float = 0.5, base_color_png: Path | None = None,
                     metallic_roughness_png: Path | None = None) -> int:
        """A general PBR material (accessories): factors, and textures when PNGs are given."""
        pbr = gl.PbrMetallicRoughness(baseColorFactor=[float(c) for c in base_color], metallicFactor=float(metallic),
                                      roughnessFactor=float(roughness))
        if base_color_png is not None:
            pbr.baseColorTexture = gl.TextureInfo(index=self.texture(f"{name}_base_color", base_color_png, True))
        if metallic_roughness_png is not None:
            pbr.metallicRoughnessTexture = gl.TextureInfo(
                index=self.texture(f"{name}_metallic_roughness", metallic_roughness_png, False))
        return self.doc.add("materials", gl.Material(name=name, pbrMetallicRoughness=pbr))


def add_variants(doc: GltfDocument, names: list[str]) -> None:
    """Declare the document's material variants (KHR_materials_variants), in order."""
    doc.use_extension(VARIANTS_EXT)
    doc.gltf.extensions[VARIANTS_EXT] = {"variants": [{"name": n} for n in names]}


def variant_mappings(materials: list[int]) -> dict:
    """The primitive extension mapping variant i to materials[i]."""
    return {VARIANTS_EXT: {"mappings": [{"material": m, "variants": [i]} for i, m in enumerate(materials)]}}
