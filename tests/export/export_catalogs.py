"""Catalogue files in the formats the textures and accessories stages write, built from test data.

`write_texture_catalog` and `write_accessory_catalog` write build/textures/catalog.json- and
build/accessories/catalog.json-style folders; every catalogue is checked against its schema
(schemas/texture_catalog.schema.json, schemas/accessory_catalog.schema.json) before it is written, so a test that
reads one reads the real format.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import jsonschema
import numpy as np
import OpenImageIO as oiio

from darthand.accessories.loader import Accessory
from darthand.fileio import sha256_file

SCHEMAS = Path(__file__).resolve().parents[2] / "schemas"
NO_HASH = "0" * 64


def check_schema(doc: dict, schema: str) -> None:
    """Raise jsonschema.ValidationError unless `doc` validates against schemas/<schema>."""
    jsonschema.Draft202012Validator(json.loads((SCHEMAS / schema).read_text())).validate(doc)


def write_png(path: Path, rgb, size: int = 32) -> Path:
    """A flat-colour 8-bit RGB PNG (rgb in 0..255)."""
    buf = oiio.ImageBuf(oiio.ImageSpec(size, size, 3, oiio.UINT8))
    oiio.ImageBufAlgo.fill(buf, [c / 255 for c in rgb])
    path.parent.mkdir(parents=True, exist_ok=True)
    assert buf.write(str(path))
    return path


def _place(src: Path, folder: Path) -> str:
    """Copy `src` into `folder` (catalogue file names are plain names in the catalogue's folder)."""
    if src.parent.resolve() != folder.resolve():
        shutil.copyfile(src, folder / src.name)
    return src.name


def write_texture_catalog(folder: Path, variants: list[tuple[str, Path, Path | None]]) -> Path:
    """folder/catalog.json listing `variants` (id, albedo PNG, roughness PNG or None), in that order; the images are
    copied into `folder`. Ids must look like the stage's (`<tone>_<category>_<NN>`)."""
    folder.mkdir(parents=True, exist_ok=True)
    entries = []
    for i, (vid, albedo, roughness) in enumerate(variants):
        files = {"albedo": _place(albedo, folder), "roughness": roughness and _place(roughness, folder), "tx": None}
        entries.append({"id": vid, "category": "freckles", "kind": "overlay", "tone": "light", "mst": 3.0,
                        "tone_srgb": [0.8, 0.6, 0.5], "offset": 0.0, "seed": i, "index": i, "resolution": 16,
                        "sha256": sha256_file(folder / files["albedo"]), "files": files, "params": {"skin": {}},
                        "fingerprint": NO_HASH})
    catalog = {"format": "darthand-texture-catalog", "version": 1, "resolution": 16, "seed": 0,
               "spec_sha256": NO_HASH,
               "bake": {"key": NO_HASH, "uvs": "model", "labels": "labels_16.png", "coverage": "coverage_16.png"},
               "model": {"source": "test", "vertices": 4, "faces": 4}, "contact_sheet": None, "entries": entries}
    check_schema(catalog, "texture_catalog.schema.json")
    (folder / "catalog.json").write_text(json.dumps(catalog))
    return folder / "catalog.json"


def write_accessory_catalog(folder: Path, accessories: list[Accessory], side: str = "right") -> Path:
    """folder/catalog.json and <id>.npz / textures for `accessories`, as the accessories stage writes them (the
    accessories' own texture files, or generated flat ones where they have none)."""
    folder.mkdir(parents=True, exist_ok=True)
    entries = []
    for acc in accessories:
        base_color = acc.base_color_png or write_png(folder / f"{acc.id}_basecolor.png", (200, 200, 200))
        mr = acc.metallic_roughness_png or write_png(folder / f"{acc.id}_metallic_roughness.png", (0, 128, 0))
        files = {"npz": f"{acc.id}.npz", "obj": f"{acc.id}.obj", "mtl": f"{acc.id}.mtl",
                 "base_color": _place(base_color, folder), "metallic_roughness": _place(mr, folder)}
        arrays = {"vertices": acc.vertices, "faces": acc.faces, "uvs": acc.uvs, "faces_uv": acc.faces_uv,
                  "parent_joint": np.array(-1 if acc.parent_joint is None else acc.parent_joint),
                  "weights": acc.weights, "posedirs": acc.posedirs}
        np.savez(folder / files["npz"], **{k: v for k, v in arrays.items() if v is not None})
        material = {"kind": "test", "metallic": 0.0, "roughness": 0.5, **acc.material,
                    "base_color_texture": files["base_color"],
                    "metallic_roughness_texture": files["metallic_roughness"]}
        entry = {"id": acc.id, "type": acc.kind, "style": "test", "parent_joint": acc.parent_joint,
                 "fitted_size": {}, "max_penetration_mm": {"rest": 0.0, "poses": None}, "files": files,
                 "material": material, "vertices": len(acc.vertices), "triangles": len(acc.faces)}
        if acc.parent_joint is not None:
            entry["rest_transform"] = np.eye(4).tolist()
        entries.append(entry)
    catalog = {"format": "darthand-accessory-catalog", "format_version": 1, "seed": 0,
               "model": {"source": "test", "side": side}, "accessories": entries}
    catalog = json.loads(json.dumps(catalog))     # as it reads back (tuples become lists)
    check_schema(catalog, "accessory_catalog.schema.json")
    (folder / "catalog.json").write_text(json.dumps(catalog))
    return folder / "catalog.json"
