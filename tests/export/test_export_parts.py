"""The parts the export writers share: pruned influences, exported correctives and their [0, 1] blend-shape encoding,
gestures, UV splitting, texture files, accessory correctives, and the texture and accessory catalogues read through
their stages' loaders, in the formats their stages write."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import UsdSkel, Vt
from scipy.spatial.transform import Rotation
from synthetic import tube_hand

from darthand.errors import InputError
from darthand.accessories.loader import Accessory, load_accessory_catalog
from darthand.export.correctives import (channel_offsets, corrective_error, corrective_names, export_correctives,
                                         exported_model, parse_correctives)
from darthand.export.gestures import gesture_poses
from darthand.export.gltf_rig import split_uv_vertices
from darthand.export.influences import dense_weights, parse_influences, top_k_influences
from darthand.export.texture_files import place_texture, texture_bytes
from darthand.textures.loader import load_texture_catalog
from darthand.fileio import sha256_file
from darthand.model.forward import forward
from darthand.model.layout import NUM_JOINTS
from darthand.model.load import TEMPLATE_DIR
from darthand.model.mirror import mirror_model
from darthand.model.wrist import add_wrist

sys.path.insert(0, str(Path(__file__).resolve().parent))

from export_catalogs import check_schema, write_accessory_catalog, write_png, write_texture_catalog  # noqa: E402


@pytest.fixture(scope="module")
def model():
    return add_wrist(tube_hand(0))


# ------------------------------------------------------------------------------------------------ influences


@pytest.mark.parametrize("k", [1, 4, 8])
def test_top_k_matches_usdskel_sort_and_resize(model, k):
    """Independent truth: UsdSkel's own SortInfluences + ResizeInfluences (which renormalises when shrinking).

    The weights are jittered so that no two joints tie (tie order is an implementation detail of each)."""
    V, J = model.weights.shape
    weights = model.weights * np.random.default_rng(k).uniform(0.9, 1.1, model.weights.shape)
    weights = (weights / weights.sum(1, keepdims=True)).astype(np.float32)
    idx = Vt.IntArray.FromNumpy(np.tile(np.arange(J, dtype=np.int32), V))
    w = Vt.FloatArray.FromNumpy(weights.reshape(-1))
    assert UsdSkel.SortInfluences(idx, w, J)
    assert UsdSkel.ResizeInfluences(idx, J, k) and UsdSkel.ResizeInfluences(w, J, k)
    ours_idx, ours_w = top_k_influences(weights, k)
    np.testing.assert_allclose(ours_w, np.asarray(w).reshape(V, k), atol=1e-6)
    positive = ours_w > 0
    np.testing.assert_array_equal(ours_idx[positive], np.asarray(idx).reshape(V, k)[positive])


def test_top_k_sorted_normalised_and_padded():
    w = np.zeros((3, NUM_JOINTS))
    w[0, [2, 5, 9]] = [0.2, 0.5, 0.3]
    w[1, 7] = 1.0
    w[2, :] = 1.0 / NUM_JOINTS
    idx, kept = top_k_influences(w, 2)
    np.testing.assert_array_equal(idx[0], [5, 9])
    np.testing.assert_allclose(kept[0], [0.625, 0.375])
    np.testing.assert_array_equal(idx[1], [7, 0])          # the empty slot points at joint 0 with weight 0
    np.testing.assert_allclose(kept[1], [1.0, 0.0])
    np.testing.assert_allclose(kept[2], [0.5, 0.5])         # ties keep joint order
    np.testing.assert_array_equal(idx[2], [0, 1])
    idx, kept = top_k_influences(w, 20)                      # more slots than joints: zero-padded
    assert idx.shape == (3, 20) and np.all(kept[:, NUM_JOINTS:] == 0)
    np.testing.assert_allclose(kept.sum(1), 1.0)
    assert np.all(np.diff(kept, axis=1) <= 0)


def test_dense_weights_round_trip(model):
    idx, w = top_k_influences(model.weights, None)
    np.testing.assert_allclose(dense_weights(idx, w), model.weights, atol=1e-15)


def test_option_parsing():
    assert parse_influences("4") == 4 and parse_influences("all") is None and parse_influences(None) is None
    assert parse_correctives("pca:32") == ("pca", 32) and parse_correctives("none") == ("none", None)
    for bad in ("0", "17", "four"):
        with pytest.raises(InputError, match="--influences"):
            parse_influences(bad)
    assert parse_correctives("pose-pca:8") == ("pose-pca", 8)
    for bad in ("pca", "pca:0", "pca:136", "pca:x", "partial", "pose-pca:", "pose-pca:-1"):
        with pytest.raises(InputError, match="--correctives"):
            parse_correctives(bad)


# ------------------------------------------------------------------------------------------------ correctives


def test_corrective_names_are_unique_identifiers():
    names = corrective_names()
    assert len(names) == 135 == len(set(names))
    assert names[0] == "pose_index1_r00" and names[-1] == "pose_thumb3_r22"
    assert all(n.isidentifier() for n in names)


def test_full_correctives_values_are_the_pose_feature(model):
    """Channel values = flatten(R_i - I), computed here with scipy's rotations: negative entries stay negative."""
    poses = np.random.default_rng(3).normal(0, 0.6, (5, 48))
    R = Rotation.from_rotvec(poses.reshape(-1, 3)).as_matrix().reshape(5, 16, 3, 3)
    expected = (R[:, 1:] - np.eye(3)).reshape(5, 135)
    full = export_correctives(model, "full")
    np.testing.assert_allclose(full.values(R), expected, atol=1e-12)
    assert (expected < 0).any() and (expected > 0).any()
    assert full.offsets is model.posedirs
    # 15 joints x (3 diagonal entries, one negative shape each + 6 off-diagonal ones, two shapes each)
    assert full.count == 15 * (3 + 12) == 225


@pytest.mark.parametrize("mode", ["full", "pca:12", "pose-pca:8"])
def test_encoded_weights_stay_in_0_1_and_reproduce_the_signed_correctives(model, mode):
    """For rotations of every size (up to pi, beyond what hands do), every exported weight lies in [0, 1] and the
    encoded shapes sum to exactly the signed corrective offset sum_k c_k d_k, computed here from the projection."""
    rng = np.random.default_rng(11)
    axes = rng.normal(size=(64, 16, 3))
    angles = rng.uniform(0, np.pi, (64, 16, 1))
    poses = (axes / np.linalg.norm(axes, axis=-1, keepdims=True) * angles).reshape(64, 48)
    poses[0] = np.tile([np.pi, 0, 0], 16)                 # R - I diagonal at its extreme -2
    c = export_correctives(model, mode)
    w = c.weights_of_poses(poses)
    assert w.min() >= 0 and w.max() <= 1
    assert mode != "full" or w.max() == 1.0               # the pose feature's bounds are attained
    R = Rotation.from_rotvec(poses.reshape(-1, 3)).as_matrix().reshape(64, 16, 3, 3)
    f = (R[:, 1:] - np.eye(3)).reshape(64, 135)
    signed = f if c.projection is None else f @ c.projection.T
    V = model.num_vertices
    exact = signed @ c.offsets.reshape(3 * V, -1).T
    encoded = w @ c.shape_offsets().reshape(3 * V, -1).T
    assert np.abs(encoded - exact).max() < 1e-12
    np.testing.assert_allclose(c.encoding.decode(w), signed, atol=1e-12)


def test_encoding_table_names_channels_and_scales(model):
    enc = export_correctives(model, "full").encoding
    table = enc.as_dict()["shapes"]
    by_name = {row["name"]: row for row in table}
    assert by_name["pose_index1_r00_neg"] == {"name": "pose_index1_r00_neg", "channel": "pose_index1_r00",
                                              "scale": -2.0}
    assert "pose_index1_r00_pos" not in by_name            # R - I is never positive on the diagonal
    assert by_name["pose_index1_r01_pos"]["scale"] == 1.0 and by_name["pose_index1_r01_neg"]["scale"] == -1.0


def test_pca_is_exact_for_low_rank_correctives(model):
    """Correctives of exact rank r: pca:K reproduces them for K >= r, and does not for K < r."""
    rng = np.random.default_rng(5)
    V, r = model.num_vertices, 6
    low = (rng.normal(0, 1e-3, (3 * V, r)) @ rng.normal(0, 1, (r, 135))).reshape(V, 3, 135)
    m = model.replace(posedirs=low)
    poses = rng.normal(0, 0.5, (8, 48))
    assert corrective_error(m, export_correctives(m, "pca:6"), poses).max() < 1e-12
    assert corrective_error(m, export_correctives(m, "pca:5"), poses).max() > 1e-6
    full_rig = forward(m, poses).vertices
    np.testing.assert_allclose(forward(exported_model(m, export_correctives(m, "pca:8")), poses).vertices,
                               full_rig, atol=1e-12)


def test_pose_pca_is_optimal_in_mean_square_over_its_pose_sample(model):
    """Eckart-Young on A L: over the very poses whose covariance defines it, pose-pca:K has the smallest mean
    squared offset error of all rank-K schemes, pca:K's included; with K = 135 it is exact."""
    from darthand.export.correctives import POSE_PCA_SAMPLES, POSE_PCA_SEED
    from darthand.model.anatomy import sample_poses

    poses = sample_poses(model, POSE_PCA_SAMPLES, np.random.default_rng(POSE_PCA_SEED))
    R = Rotation.from_rotvec(poses.reshape(-1, 3)).as_matrix().reshape(len(poses), 16, 3, 3)
    f = (R[:, 1:] - np.eye(3)).reshape(len(poses), 135)
    A = model.posedirs.reshape(-1, 135)
    second_moment = f.T @ f / len(f)

    def mse(mode):
        """E ||A f - B P f||^2 = trace((A - B P) C (A - B P)^T) over the sample."""
        c = export_correctives(model, mode)
        D = A - c.offsets.reshape(len(A), -1) @ c.projection
        return float(np.einsum("ij,jk,ik->", D, second_moment, D))

    for k in (4, 16):
        assert mse(f"pose-pca:{k}") < mse(f"pca:{k}")
    assert mse("pose-pca:135") < 1e-12 * mse("pca:4")


def test_pca_error_shrinks_with_k_and_none_drops_correctives(model):
    poses = np.random.default_rng(6).normal(0, 0.5, (16, 48))
    errs = [corrective_error(model, export_correctives(model, f"pca:{k}"), poses).max() for k in (8, 32, 64, 135)]
    assert errs[0] > errs[1] > errs[2] > errs[3] and errs[3] < 1e-12
    none = exported_model(model, export_correctives(model, "none"))
    np.testing.assert_allclose(forward(none, poses).vertices, forward(model, poses, correctives=False).vertices,
                               atol=1e-14)


# ------------------------------------------------------------------------------------------------ gestures, UVs


def test_gesture_poses_start_with_the_rest_pose(model):
    names, poses = gesture_poses(model)
    assert poses.shape == (len(names), 48) and len(set(names)) == len(names)
    if names != ["rest"]:
        assert names[0] == "flat" and np.all(poses[0] == 0) and np.abs(poses[1:]).max() > 0.1


def test_split_uv_vertices_reproduces_corners(model):
    source, uvs, faces = split_uv_vertices(model.faces, model.faces_uv, model.uvs)
    np.testing.assert_array_equal(uvs[faces], model.uvs[model.faces_uv])
    np.testing.assert_array_equal(source[faces], model.faces)
    assert len(source) == len(np.unique(np.stack([model.faces.ravel(), model.faces_uv.ravel()], 1), axis=0))


def test_split_uv_vertices_without_uvs_keeps_the_used_vertices_in_order():
    faces = np.array([[0, 2, 3], [3, 2, 5]])                   # vertices 1 and 4 are unused
    source, uvs, new_faces = split_uv_vertices(faces)
    assert uvs is None
    np.testing.assert_array_equal(source, [0, 2, 3, 5])
    np.testing.assert_array_equal(source[new_faces], faces)
    seamless = np.array([[0, 1, 2], [2, 1, 3]])                 # no seam, no unused vertex: the identity
    source, uvs, new_faces = split_uv_vertices(seamless, seamless, np.random.default_rng(0).random((4, 2)))
    np.testing.assert_array_equal(source, np.arange(4))
    np.testing.assert_array_equal(new_faces, seamless)


# ------------------------------------------------------------------------------------------------ texture files


def test_textures_are_downsized_in_linear_light_never_upsized(tmp_path):
    """A 40 x 20 black/white checker: size 10 gives 10 x 5 whose pixels are the linear-light mean 0.5, i.e. sRGB
    188/255 (not the sRGB mean 128; the resize filter rings by a level or two at the borders); a size at least
    the image's links or copies it unchanged."""
    import OpenImageIO as oiio

    checker = (np.indices((20, 40)).sum(axis=0) % 2 * 255).astype(np.uint8)
    src = tmp_path / "checker.png"
    buf = oiio.ImageBuf(oiio.ImageSpec(40, 20, 3, oiio.UINT8))
    buf.set_pixels(oiio.ROI(0, 40, 0, 20, 0, 1, 0, 3), np.repeat(checker[..., None], 3, axis=2))
    assert buf.write(str(src))
    place_texture(src, tmp_path / "small.png", size=10)
    small = oiio.ImageBuf(str(tmp_path / "small.png"))
    assert (small.spec().width, small.spec().height) == (10, 5)
    linear_half = round(255 * (1.055 * 0.5 ** (1 / 2.4) - 0.055))                          # 188
    assert np.abs(small.get_pixels(oiio.UINT8).astype(int) - linear_half).max() <= 3   # filter ringing at edges
    assert texture_bytes(src, 10) == (tmp_path / "small.png").read_bytes()
    place_texture(src, tmp_path / "same.png", size=64)
    assert (tmp_path / "same.png").read_bytes() == src.read_bytes() == texture_bytes(src, 40)
    with pytest.raises(InputError, match="missing.png: texture file not found"):
        place_texture(tmp_path / "missing.png", tmp_path / "x.png")


# ------------------------------------------------------------------------------------------------ accessories


def test_channel_offsets_fit_the_accessory_correctives_in_the_hand_basis(model):
    """D = G P^+: the glove's own correctives G carried by the hand's blend-shape weights c = P f.

    full: D = G. pca:K (P = W_K, orthonormal rows): D c = G W_K^T W_K f, the projection of f on the top right
    singular vectors, computed here with our own SVD. pose-pca:K: D is the least-squares solution of D P = G,
    checked through its normal equations (D P - G) P^T = 0 and against a different D (the transpose formula).
    """
    G = np.random.default_rng(8).normal(0, 1e-3, model.posedirs.shape)
    glove = Accessory("glove", model.v_template, model.faces, weights=model.weights, posedirs=G)
    assert channel_offsets(glove.posedirs, export_correctives(model, "full"), len(G)) is G
    none = channel_offsets(glove.posedirs, export_correctives(model, "none"), len(G))
    assert none.shape == (model.num_vertices, 3, 0)
    f = np.random.default_rng(9).normal(0, 0.3, (5, 135))
    W = np.linalg.svd(model.posedirs.reshape(-1, 135), full_matrices=False)[2][:8]
    pca = export_correctives(model, "pca:8")
    D = channel_offsets(glove.posedirs, pca, len(G))
    np.testing.assert_allclose(np.einsum("nck,bk->bnc", D, f @ pca.projection.T),
                               np.einsum("nck,bk->bnc", G, f @ W.T @ W), atol=1e-15)
    pose_pca = export_correctives(model, "pose-pca:8")
    P = pose_pca.projection
    D = channel_offsets(glove.posedirs, pose_pca, len(G))
    residual = (D @ P - G).reshape(-1, 135) @ P.T
    assert np.abs(residual).max() < 1e-9 * np.abs(G.reshape(-1, 135) @ P.T).max()
    transpose = (G @ P.T).reshape(-1, 8)                       # what treating P as orthonormal would give
    assert np.abs(transpose - D.reshape(-1, 8)).max() > 1e-3 * np.abs(D).max()


# ------------------------------------------------------------------------------------------------ catalogues


def test_texture_catalogue_in_the_stage_format(tmp_path):
    a = write_png(tmp_path / "src" / "a.png", (200, 150, 120))
    rough = write_png(tmp_path / "src" / "rough.png", (128, 128, 128))
    catalog = write_texture_catalog(tmp_path / "tex", [("light_freckles_00", a, None),
                                                       ("dark_tattoos_01", a, rough)])
    sets = load_texture_catalog(catalog)
    assert [s.id for s in sets] == ["light_freckles_00", "dark_tattoos_01"]
    assert sets[0].albedo == tmp_path / "tex" / "a.png" and sets[0].albedo.read_bytes() == a.read_bytes()
    assert sets[0].roughness is None and sets[1].roughness == tmp_path / "tex" / "rough.png"
    assert load_texture_catalog(tmp_path / "tex") == sets      # the folder works too
    doc = json.loads(catalog.read_text())
    doc["default"] = "dark_tattoos_01"
    catalog.write_text(json.dumps(doc))
    assert [s.id for s in load_texture_catalog(catalog)] == ["dark_tattoos_01", "light_freckles_00"]


def test_texture_catalogue_written_by_the_textures_stage(model, tmp_path):
    """The textures stage's own output (a two-variant build at 16 px) validates against the schema and loads."""
    from darthand.textures.build import build_textures
    from darthand.textures.catalog import expand_catalog, load_spec

    spec = load_spec()
    ids = [e.id for e in expand_catalog(spec)][:2]
    built = build_textures(model, spec, tmp_path, res=16, ids=ids, workers=1, progress=False, tx=False,
                           sheet=False)
    check_schema(built, "texture_catalog.schema.json")
    sets = load_texture_catalog(tmp_path)
    assert [s.id for s in sets] == ids
    for s, entry in zip(sets, built["entries"]):
        assert sha256_file(s.albedo) == entry["sha256"] and s.roughness.is_file()


def ring_and_glove(model):
    ring = Accessory("ring_x", model.v_template[:10], np.array([[0, 1, 2], [2, 1, 3], [4, 5, 6], [6, 5, 7]]),
                     uvs=np.zeros((8, 2)), faces_uv=np.array([[0, 1, 2], [2, 1, 3], [4, 5, 6], [6, 5, 7]]),
                     parent_joint=10, material={"base_color": [0.9, 0.7, 0.2], "metallic": 1.0, "roughness": 0.3},
                     kind="ring")
    glove = Accessory("glove_y", model.v_template, model.faces, uvs=model.uvs, faces_uv=model.faces_uv,
                      weights=model.weights, posedirs=model.posedirs, kind="glove")
    return ring, glove


def test_accessory_catalogue_in_the_stage_format(tmp_path, model):
    ring, glove = ring_and_glove(model)
    catalog = write_accessory_catalog(tmp_path / "acc", [ring, glove], side="right")
    got_ring, got_glove = load_accessory_catalog(catalog, side="right")
    assert got_ring.parent_joint == 10 and got_ring.kind == "ring" and not got_ring.skinned
    assert got_ring.material["metallic"] == 1.0 and got_ring.base_color_png.is_file()
    np.testing.assert_array_equal(got_ring.vertices, ring.vertices)
    np.testing.assert_array_equal(got_ring.faces_uv, ring.faces_uv)
    assert got_glove.skinned and got_glove.parent_joint is None and got_glove.kind == "glove"
    np.testing.assert_array_equal(got_glove.posedirs, glove.posedirs)
    assert [a.id for a in load_accessory_catalog(tmp_path / "acc", ["glove_y"])] == ["glove_y"]
    left_ring, left_glove = load_accessory_catalog(tmp_path / "acc", side="left")   # fitted to the right hand
    np.testing.assert_array_equal(left_ring.vertices, ring.vertices * [-1, 1, 1])
    np.testing.assert_array_equal(left_ring.faces, ring.faces[:, [0, 2, 1]])
    left = mirror_model(model)
    np.testing.assert_allclose(left_glove.posedirs, left.posedirs, atol=0)          # as mirror_model does it


@pytest.mark.skipif(not (TEMPLATE_DIR / "open_right.npz").is_file(), reason="no open hand template in this checkout")
def test_accessory_catalogue_written_by_the_accessories_stage(tmp_path):
    """The accessories stage's own output (a ring and a glove on the open hand) validates and loads; the loaded
    rest vertices are the npz's local vertices placed by the entry's rest transform (model frame)."""
    from darthand.accessories.build import build_accessories
    from darthand.accessories.catalog import load_spec
    from darthand.model.load import load_model

    spec = load_spec()
    first = {}
    for item in spec["items"]:
        first.setdefault(item["type"], item["id"])
    hand = add_wrist(load_model("open"))
    built = build_accessories(hand, spec, tmp_path, ids=[first["ring"], first["glove"]], n_sampled=0, gestures=[],
                              refit=False, sheet=False)
    check_schema(built, "accessory_catalog.schema.json")
    ring, glove = load_accessory_catalog(tmp_path, side="right")
    entry = built["accessories"][0]
    assert ring.id == entry["id"] and ring.parent_joint == entry["parent_joint"] and not ring.skinned
    with np.load(tmp_path / entry["files"]["npz"]) as z:
        placed = z["local_vertices"] @ np.asarray(entry["rest_transform"])[:3, :3].T + \
            np.asarray(entry["rest_transform"])[:3, 3]
    np.testing.assert_allclose(ring.vertices, placed, atol=1e-12)
    assert ring.base_color_png.is_file() and ring.metallic_roughness_png.is_file()
    assert glove.skinned and glove.weights.shape == (len(glove.vertices), 16)
    assert glove.posedirs.shape == (len(glove.vertices), 3, 135)


def test_catalogue_errors_name_the_file_and_field(tmp_path, model):
    a = write_png(tmp_path / "a.png", (10, 20, 30))
    tex = write_texture_catalog(tmp_path / "tex", [("light_freckles_00", a, None)])
    with pytest.raises(InputError, match="missing.json: no such texture catalogue"):
        load_texture_catalog(tmp_path / "missing.json")
    doc = json.loads(tex.read_text())
    del doc["entries"][0]["files"]["albedo"]
    tex.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"catalog.json: field 'entries.0.files' 'albedo' is a required property"):
        load_texture_catalog(tex)
    tex.write_text(json.dumps([{"id": "x", "files": {"albedo": "a.png"}}]))    # an older, guessed layout
    with pytest.raises(InputError, match=r"catalog.json: field '\(top level\)' .* is not of type 'object'"):
        load_texture_catalog(tex)
    acc = write_accessory_catalog(tmp_path / "acc", ring_and_glove(model)[:1])
    doc = json.loads(acc.read_text())
    doc["accessories"][0]["parent_joint"] = "ring1"
    acc.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"catalog.json: field 'accessories.0.parent_joint'"):
        load_accessory_catalog(acc)
    doc["accessories"][0]["parent_joint"] = 10
    acc.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="no accessory with id 'nope'"):
        load_accessory_catalog(acc, ["nope"])
    (tmp_path / "acc" / "ring_x.npz").unlink()
    with pytest.raises(InputError, match="ring_x.npz: unreadable accessory mesh"):
        load_accessory_catalog(acc)
