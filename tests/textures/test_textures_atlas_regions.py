"""UV atlases for models without UVs (xatlas), seam edges, and semantic labels derived from geometry."""

from pathlib import Path

import numpy as np
import pytest

from darthand.model.layout import FACE_LABEL_IDS, FACE_LABELS
from darthand.model.atlas import atlas_padding, compute_atlas, ensure_uvs, seam_edges
from darthand.textures.raster import rasterize
from darthand.model.regions import derive_face_labels, ensure_face_labels, skeleton
from texture_hand import fixture_model

TEMPLATE = Path(__file__).resolve().parents[2] / "assets_src" / "template" / "open_right.npz"


def test_models_with_uvs_keep_them():
    m = fixture_model()
    assert ensure_uvs(m, 256) is m


def test_atlas_is_deterministic_and_covers_every_face_without_overlap():
    m = fixture_model(with_uvs=False)
    res = 256
    a = ensure_uvs(m, res)
    b = ensure_uvs(m, res)
    assert np.array_equal(a.uvs, b.uvs) and np.array_equal(a.faces_uv, b.faces_uv)
    assert a.meta["uv_atlas"]["generator"] == "xatlas" and a.meta["uv_atlas"]["padding"] == atlas_padding(res)
    assert a.uvs.min() >= 0.0 and a.uvs.max() <= 1.0
    # Every face keeps its 3D corners (faces_uv maps back onto the same triangle shape up to scale).
    tri = a.uvs[a.faces_uv] * res
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    area2 = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    assert (area2 > 0).all()
    # No overlap: the rasterised texel count equals the sum of per-face texel counts.
    total = sum(len(rasterize(t[None], res, res).pixel) for t in tri)
    union = len(rasterize(tri, res, res).pixel)
    assert union == total
    # Charts fill the square reasonably (the density search works).
    assert union / res ** 2 > 0.3


def test_atlas_charts_are_padded_apart():
    m = fixture_model(with_uvs=False)
    res = 256
    uvs, faces_uv = compute_atlas(m.v_template, m.faces, res)
    tri = np.stack([uvs[faces_uv][..., 0] * res, (1 - uvs[faces_uv][..., 1]) * res], -1)
    frags = rasterize(tri, res, res)
    # Charts = connected components of faces through shared UV vertices.
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    F = len(faces_uv)
    rows = np.repeat(np.arange(F), 3)
    g = coo_matrix((np.ones(3 * F), (rows, faces_uv.ravel())), shape=(F, len(uvs))).tocsr()
    _, chart_of_face = connected_components(g @ g.T, directed=False)
    chart = np.full(res * res, -1)
    chart[frags.pixel] = chart_of_face[frags.face]
    img = chart.reshape(res, res)
    pad = atlas_padding(res)
    # Any two covered texels of different charts are more than pad - 1 texels apart (xatlas pads the chart
    # outlines; rasterised centres may sit up to a texel inside them).
    r, c = np.nonzero(img >= 0)
    ids = img[r, c]
    from scipy.spatial import cKDTree

    tree = cKDTree(np.stack([r, c], 1))
    pairs = tree.query_pairs(pad - 1.0, output_type="ndarray")
    assert (ids[pairs[:, 0]] == ids[pairs[:, 1]]).all()


def test_seam_edges_of_a_cylinder_cut():
    m = fixture_model()
    seams = seam_edges(m.faces, m.faces_uv, m.uvs)
    # Each tube is cut once along its length: a seam edge per ring gap, per tube (palm + 5 fingers).
    assert len(seams["vertices"]) > 0
    uv = seams["uv"]
    assert (np.abs(uv[:, 0] - uv[:, 1]).max(axis=(1, 2)) > 1e-9).all()
    # Both faces of a seam edge share the two 3D vertices.
    for (a, b), (f, g) in zip(seams["vertices"], seams["faces"]):
        assert {a, b} <= set(m.faces[f]) and {a, b} <= set(m.faces[g])


def test_derived_labels_match_the_fixture_construction():
    m = fixture_model()
    truth = m.face_labels
    derived = derive_face_labels(m)
    assert derived.shape == truth.shape and derived.dtype == np.int8
    assert (derived >= 0).all()
    wrist = FACE_LABEL_IDS["wrist"]
    assert np.array_equal(derived == wrist, truth == wrist)
    back = np.isin(truth, [FACE_LABEL_IDS[n] for n in ("dorsum", "finger_dorsal", "nail")])
    back_d = np.isin(derived, [FACE_LABEL_IDS[n] for n in ("dorsum", "finger_dorsal", "nail")])
    assert (back == back_d)[truth != wrist].mean() > 0.95
    nail, nail_d = truth == FACE_LABEL_IDS["nail"], derived == FACE_LABEL_IDS["nail"]
    assert (nail & nail_d).sum() / (nail | nail_d).sum() > 0.5
    # Every finger gets a nail, on its distal segment.
    skel = skeleton(m)
    from darthand.textures.anatomy import face_bones

    bones = face_bones(m.v_template, m.faces, skel)
    assert set(bones[nail_d]) == {2, 5, 8, 11, 14}


def test_ensure_face_labels_fills_only_missing():
    m = fixture_model(with_labels=False)
    filled = ensure_face_labels(m)
    assert filled.face_labels is not None and (filled.face_labels >= 0).all()
    m2 = fixture_model()
    assert ensure_face_labels(m2) is m2


@pytest.mark.skipif(not TEMPLATE.is_file(), reason="open template not in this checkout")
def test_derived_labels_agree_with_the_open_templates_artist_labels():
    from darthand.model.npz_io import load_npz

    m = load_npz(TEMPLATE)
    derived = derive_face_labels(m)
    back = np.isin(m.face_labels, [FACE_LABEL_IDS[n] for n in ("dorsum", "finger_dorsal", "nail")])
    back_d = np.isin(derived, [FACE_LABEL_IDS[n] for n in ("dorsum", "finger_dorsal", "nail")])
    keep = m.face_labels != FACE_LABEL_IDS["wrist"]
    assert (back == back_d)[keep].mean() > 0.85
    for name in FACE_LABELS:
        assert (derived == FACE_LABEL_IDS[name]).any(), name
