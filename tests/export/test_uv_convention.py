"""One UV convention from the textures stage to the engines: the model's UVs are OpenGL / OBJ / USD `st` style
(v up, (0, 0) at the image's bottom-left), glTF stores (u, 1 - v) (its origin is the top-left).

Truth is the textures stage's own baked label map (labels_<res>.png: the face label of every texel whose centre
lies on the surface, row 0 at the top of the file). The tube hand's faces get labels by band along the tube (v),
so a v-flip anywhere moves a face into another band. For every face, the texel under its centroid texture
coordinate as stored in the exported file -- glTF: row = t * H; USD st: row = (1 - t) * H -- must carry its label.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from pxr import Usd, UsdGeom
from synthetic import tube_hand

from darthand.export.gltf_export import GltfOptions, export_gltf
from darthand.export.usd_asset import export_usd

sys.path.insert(0, str(Path(__file__).resolve().parent))

from test_gltf_reference import GltfFile  # noqa: E402

RES = 64
BANDS = 4


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    """(model with banded face labels, the label map the textures stage baked for it (RES, RES) uint8)."""
    from darthand.textures.build import build_textures
    from darthand.textures.catalog import expand_catalog, load_spec

    model = tube_hand(0)
    v = model.uvs[model.faces_uv][:, :, 1].mean(axis=1)                      # face centroid v
    labels = np.minimum((v * BANDS).astype(np.int8), BANDS - 1)
    model = model.replace(face_labels=labels)
    folder = tmp_path_factory.mktemp("textures")
    spec = load_spec()
    catalog = build_textures(model, spec, folder, res=RES, ids=[expand_catalog(spec)[0].id], workers=1,
                             progress=False, tx=False, roughness=False, sheet=False)
    label_map = oiio.ImageBuf(str(folder / catalog["bake"]["labels"])).get_pixels(oiio.UINT8)[..., 0]
    assert set(np.unique(label_map)) == set(range(BANDS)) | {255}
    return model, label_map


def texel_labels(label_map: np.ndarray, corner_uv: np.ndarray, flip: bool) -> np.ndarray:
    """Label of the texel under each face's centroid, corner_uv (F, 3, 2) in the file's convention; `flip`: row
    counted from the bottom (v up) instead of the top."""
    u, t = corner_uv.mean(axis=1).T
    col = np.clip((u * RES).astype(int), 0, RES - 1)
    row = np.clip(((1.0 - t if flip else t) * RES).astype(int), 0, RES - 1)
    return label_map[row, col]


def checked_faces(model) -> np.ndarray:
    """Faces whose own UV triangle holds the centre of the texel under their centroid (so that texel is theirs),
    leaving out those that wrap around the tube's seam (they span the whole image width)."""
    uv = model.uvs[model.faces_uv]                                          # (F, 3, 2), v up
    centre_px = np.floor(uv.mean(axis=1) * RES) + 0.5                       # texel centre, in (u, v) pixel units
    a, b, c = uv[:, 0] * RES, uv[:, 1] * RES, uv[:, 2] * RES

    def cross(p, q, r):
        return (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])

    signs = np.stack([cross(a, b, centre_px), cross(b, c, centre_px), cross(c, a, centre_px)], axis=1)
    inside = np.all(signs > 0, axis=1) | np.all(signs < 0, axis=1)
    wraps = np.ptp(uv[:, :, 0], axis=1) > 0.5
    faces = np.flatnonzero(inside & ~wraps)
    assert len(faces) > 0.8 * (~wraps).sum()
    return faces


def test_textures_stage_bakes_v_up(baked):
    """Row 0 of the baked map is v = 1: the band of the highest v is at the top of the image."""
    model, label_map = baked
    faces = checked_faces(model)
    got = texel_labels(label_map, model.uvs[model.faces_uv][faces], flip=True)
    np.testing.assert_array_equal(got, model.face_labels[faces])
    assert np.all(label_map[:2][label_map[:2] != 255] == BANDS - 1)


def test_gltf_texcoords_address_the_baked_texels(baked, tmp_path):
    model, label_map = baked
    out = tmp_path / "hand.glb"
    export_gltf(model, out, gestures=([], np.zeros((0, 48))), options=GltfOptions(influences=None))
    f = GltfFile(out)
    prim = f.doc.meshes[0].primitives[0]
    ids = f.attr(prim, "_VERTEX_ID")[:, 0].astype(int)
    tri = f.accessor(prim.indices)[:, 0].reshape(-1, 3).astype(int)
    texcoord = f.attr(prim, "TEXCOORD_0")
    # the file's triangles are the model's, in order: map each back to its model face through the vertex ids
    np.testing.assert_array_equal(ids[tri], model.faces)
    faces = checked_faces(model)
    got = texel_labels(label_map, texcoord[tri][faces], flip=False)        # glTF: origin top-left
    np.testing.assert_array_equal(got, model.face_labels[faces])


def test_usd_st_addresses_the_baked_texels(baked, tmp_path):
    model, label_map = baked
    info = export_usd(model, tmp_path / "right", gestures=(["flat"], np.zeros((1, 48))))
    stage = Usd.Stage.Open(str(tmp_path / "right" / info["interface"]), Usd.Stage.LoadAll)
    st = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/RightHand/RightHandMesh")).GetPrimvar("st")
    corner_st = np.asarray(st.ComputeFlattened(), dtype=np.float64).reshape(-1, 3, 2)   # faceVarying, face order
    faces = checked_faces(model)
    got = texel_labels(label_map, corner_st[faces], flip=True)             # USD st: origin bottom-left
    np.testing.assert_array_equal(got, model.face_labels[faces])
