"""Good packages, built once per session by the writers' public APIs: a USD package (two skin textures, a rigid
ring and a skinned glove as variants) and the same content as .glb and as a .gltf folder. Every broken fixture
is an edited copy of one of them (corpus.py)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from synthetic import tube_hand  # noqa: E402

from darthand.accessories.loader import Accessory  # noqa: E402
from darthand.textures.loader import TextureSet  # noqa: E402
from darthand.model.topology import vertex_normals  # noqa: E402
from darthand.model.wrist import add_wrist  # noqa: E402

from package_parts import GESTURES, GLOVE_ID, RING_ID, RING_JOINT, TEXTURE_IDS, ring_mesh, write_png  # noqa: E402


@pytest.fixture(scope="session")
def model():
    return add_wrist(tube_hand(0))


@pytest.fixture(scope="session")
def sources(model, tmp_path_factory):
    src = tmp_path_factory.mktemp("sources")
    textures = [TextureSet(TEXTURE_IDS[0], write_png(src / "t0" / "albedo.png", 32, 32, 0),
                           write_png(src / "t0" / "roughness.png", 32, 32, 1)),
                TextureSet(TEXTURE_IDS[1], write_png(src / "t1" / "albedo.png", 32, 32, 2))]
    ring_v, ring_f = ring_mesh(model)
    glove_v = model.v_template + 0.001 * vertex_normals(model.v_template, model.faces)
    accessories = [
        Accessory(RING_ID, ring_v, ring_f, parent_joint=RING_JOINT, kind="ring",
                  base_color_png=write_png(src / "ring" / "base.png", 16, 16, 3),
                  uvs=np.random.default_rng(4).random((len(ring_v), 2)), faces_uv=ring_f,
                  material={"base_color": [1.0, 0.8, 0.3, 1.0], "metallic": 1.0, "roughness": 0.3}),
        Accessory(GLOVE_ID, glove_v, model.faces, uvs=model.uvs, faces_uv=model.faces_uv, weights=model.weights,
                  posedirs=model.posedirs, kind="glove"),
    ]
    return textures, accessories


@pytest.fixture(scope="session")
def good_usd(model, sources, tmp_path_factory) -> Path:
    """build .../usd/right/ (right.usda, payload.usdc, texture/, accessory/, asset.json)."""
    from darthand.export.usd_asset import export_usd

    textures, accessories = sources
    out = tmp_path_factory.mktemp("usd") / "right"
    export_usd(model, out, textures=textures, accessories=accessories, gestures=GESTURES)
    return out


def _export_gltf(model, sources, out: Path) -> Path:
    from darthand.export.gltf_export import export_gltf

    textures, accessories = sources
    out.parent.mkdir(parents=True, exist_ok=True)
    export_gltf(model, out, textures=textures, accessories=accessories, gestures=GESTURES)
    return out


@pytest.fixture(scope="session")
def good_glb(model, sources, tmp_path_factory) -> Path:
    return _export_gltf(model, sources, tmp_path_factory.mktemp("glb") / "right.glb")


@pytest.fixture(scope="session")
def good_gltf(model, sources, tmp_path_factory) -> Path:
    """A .gltf package: right.gltf, right.bin, textures/*.png."""
    return _export_gltf(model, sources, tmp_path_factory.mktemp("gltf") / "pkg" / "right.gltf")
