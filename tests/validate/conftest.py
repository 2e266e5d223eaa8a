"""Good packages, built once per session by the writers' public APIs: a USD package (two skin textures, a rigid
ring and a skinned glove as variants) and the same content as .glb and as a .gltf folder. Every broken fixture
is an edited copy of one of them (corpus.py)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from synthetic import tube_hand  # noqa: E402

from darthand.accessories.loader import Accessory  # noqa: E402
from darthand.textures.loader import TextureSet  # noqa: E402
from darthand.model.topology import vertex_normals  # noqa: E402
from darthand.model.wrist import add_wrist  # noqa: E402

# Catalogue ids of the committed specs (the packages have no built catalogue beside them).
TEXTURE_IDS = ("light_tattoos_00", "base_freckles_00")
RING_ID, GLOVE_ID = "ring_01_court_gold", "glove_01_latex"
RING_JOINT = 5            # middle2
RING_GAP = 0.0008         # metres between the ring's inner surface and the hand's
GESTURES = (["flat", "fist_like"], np.stack([np.zeros(48), np.r_[np.zeros(3), np.tile([0, 0, 0.6], 15)]]))


def write_png(path: Path, width: int, height: int, seed: int) -> Path:
    rgb = np.random.default_rng(seed).random((height, width, 3)).astype(np.float32)
    buf = oiio.ImageBuf(oiio.ImageSpec(width, height, 3, oiio.UINT8))
    buf.set_pixels(oiio.ROI(), rgb)
    path.parent.mkdir(parents=True, exist_ok=True)
    assert buf.write(str(path)), buf.geterror()
    return path


def ring_mesh(model, joint: int = RING_JOINT, segments: int = 24, tube: int = 6, minor: float = 0.0005):
    """A closed torus around the finger tube (axis X) at the joint's x, its inner surface RING_GAP outside the
    tube's inscribed circle (the tube is a 16-gon of radius 3 cm)."""
    centre = np.asarray(model.J_regressor @ model.v_template)[joint]
    inradius = 0.03 * np.cos(np.pi / 16)
    major = inradius + RING_GAP + minor
    u = 2 * np.pi * np.arange(segments)[:, None] / segments
    v = 2 * np.pi * np.arange(tube)[None, :] / tube
    r = major + minor * np.cos(v) + 0 * u
    x = np.broadcast_to(centre[0] + minor * np.sin(v), r.shape)
    verts = np.stack([x, r * np.cos(u) + 0 * x, r * np.sin(u) + 0 * x], -1)
    faces = []
    for i in range(segments):
        for j in range(tube):
            a, b = i * tube + j, ((i + 1) % segments) * tube + j
            c, d = i * tube + (j + 1) % tube, ((i + 1) % segments) * tube + (j + 1) % tube
            faces += [(a, b, d), (a, d, c)]
    verts = verts.reshape(-1, 3)
    faces = np.array(faces)
    # outward winding: positive signed volume
    a, b, c = (verts[faces[:, k]] for k in range(3))
    if np.einsum("ij,ij->i", a, np.cross(b, c)).sum() < 0:
        faces = faces[:, ::-1].copy()
    return verts, faces


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
