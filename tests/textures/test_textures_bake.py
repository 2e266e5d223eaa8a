"""Rasterisation and baking against closed-form cases; padding a baked image; the bake cache."""

import numpy as np
import pytest
import scipy.sparse as sp

from darthand.model.hand_model import HandModel
from darthand.model.layout import FACE_LABEL_IDS, MANO_PARENTS, NUM_POSE_FEATURES
from darthand.textures.bake import bake, bake_key, cached_bake, load_bake, save_bake
from darthand.textures.raster import rasterize
from texture_hand import fixture_bake, fixture_model


def test_rasterize_matches_point_in_triangle_test():
    rng = np.random.default_rng(3)
    tri = rng.uniform(0, 40, (6, 3, 2))
    frags = rasterize(tri, 40, 40)
    rows, cols = np.divmod(frags.pixel, 40)
    centres = np.stack([cols + 0.5, rows + 0.5], 1)
    # Independent truth: sign of the three edge functions, for every pixel and triangle.
    ys, xs = np.mgrid[0:40, 0:40]
    p = np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], 1)
    inside_any = np.zeros(len(p), bool)
    for t in tri:
        s = [(t[(i + 1) % 3][0] - t[i][0]) * (p[:, 1] - t[i][1]) - (t[(i + 1) % 3][1] - t[i][1]) * (p[:, 0] - t[i][0])
         for i in range(3)]
        inside_any |= ((s[0] >= 0) & (s[1] >= 0) & (s[2] >= 0)) | ((s[0] <= 0) & (s[1] <= 0) & (s[2] <= 0))
    assert set(frags.pixel) == set(np.nonzero(inside_any)[0])
    # Each pixel's barycentrics reproduce its centre from its triangle's corners.
    recon = np.einsum("nk,nki->ni", frags.bary, tri[frags.face])
    assert np.allclose(recon, centres, atol=1e-9)


def _point_triangle_distance(p, t):
    """Scalar reference: 0 inside, else the smallest point-to-edge-segment distance."""
    signs = []
    for i in range(3):
        a, b = t[i], t[(i + 1) % 3]
        signs.append(np.sign((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])))
    if all(s >= 0 for s in signs) or all(s <= 0 for s in signs):
        return 0.0
    best = np.inf
    for i in range(3):
        a, b = t[i], t[(i + 1) % 3]
        h = min(max(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0.0), 1.0)
        best = min(best, float(np.linalg.norm(p - (a + h * (b - a)))))
    return best


def test_rasterize_margin_gives_distance_to_triangle():
    tri = np.array([[[2.0, 2.0], [12.0, 3.0], [4.0, 12.0]]])
    frags = rasterize(tri, 16, 16, margin=2.0)
    expected = {}
    for r in range(16):
        for c in range(16):
            d = _point_triangle_distance(np.array([c + 0.5, r + 0.5]), tri[0])
            if d <= 2.0:
                expected[r * 16 + c] = d
    assert set(frags.pixel.tolist()) == set(expected)
    assert np.allclose(frags.distance, [expected[p] for p in frags.pixel], atol=1e-9)
    # Barycentrics of margin pixels name the nearest point of the triangle, at that distance.
    rows, cols = np.divmod(frags.pixel, 16)
    nearest = frags.bary @ tri[0]
    assert np.allclose(np.hypot(nearest[:, 0] - cols - 0.5, nearest[:, 1] - rows - 0.5), frags.distance, atol=1e-9)
    assert (frags.bary >= -1e-12).all() and np.allclose(frags.bary.sum(1), 1.0)


def _quad_model(labels=(1, 2)):
    """A flat 10 cm square in the y = 0 plane (two triangles, UVs covering [0.25, 0.75]^2), with the 16 joints
    and 5 tips of synthetic.joint_positions as extra vertices off the square (so the rig is well formed)."""
    from synthetic import joint_positions

    joints = joint_positions()
    quad = np.array([[0.0, 0, 0], [0.1, 0, 0], [0.1, 0, 0.1], [0.0, 0, 0.1]])
    tips = joints[[15, 3, 6, 12, 9]] + [-0.02, 0, 0]
    v = np.concatenate([quad, joints, tips]) + [0.0, 0.0, 0.0]
    V = len(v)
    regressor = sp.csr_matrix((np.ones(16), (np.arange(16), 4 + np.arange(16))), shape=(16, V))
    return HandModel.create(
        v_template=v, faces=np.array([[0, 2, 1], [0, 3, 2]]), weights=np.full((V, 16), 1 / 16),
        posedirs=np.zeros((V, 3, NUM_POSE_FEATURES)), J_regressor=regressor, parents=MANO_PARENTS,
        tip_ids=20 + np.arange(5), uvs=np.array([[0.25, 0.25], [0.75, 0.25], [0.75, 0.75], [0.25, 0.75]]),
        faces_uv=np.array([[0, 2, 1], [0, 3, 2]]), face_labels=np.array(labels))


def test_bake_flat_quad_positions_normals_labels_closed_form():
    res = 64
    b = bake(_quad_model(), res)
    rows, cols = np.divmod(b.texel, res)
    u, v = (cols + 0.5) / res, 1 - (rows + 0.5) / res
    inside = b.inside
    # UV (0.25..0.75) maps linearly to x, z (0..0.1 m): the barycentric truth on a flat quad.
    assert np.allclose(b.position[inside, 0], (u[inside] - 0.25) * 0.2, atol=1e-6)
    assert np.allclose(b.position[inside, 2], (v[inside] - 0.25) * 0.2, atol=1e-6)
    assert np.allclose(b.position[:, 1], 0.0, atol=1e-7)
    assert np.allclose(np.abs(b.normal[:, 1]), 1.0, atol=1e-6)
    # Coverage: exactly the texels whose centres lie in the UV square.
    expected = (u > 0.25) & (u < 0.75) & (v > 0.25) & (v < 0.75)
    assert inside.sum() == expected.sum() and (inside == expected).all()
    # Labels: the face's label, split along the diagonal u = v (face 0 below, face 1 above).
    below = u > v + 1e-9
    assert (b.label[inside & below] == 1).all() and (b.label[inside & ~below & (u < v - 1e-9)] == 2).all()
    # Gutter texels hold the nearest point of their face: still on the quad, within MARGIN texels.
    g = ~inside
    assert g.any()
    assert (b.position[g, 0] >= -1e-9).all() and (b.position[g, 0] <= 0.1 + 1e-9).all()


def test_padding_keeps_every_mip_block_within_its_own_stored_colours():
    """Push-pull on the pyramid's blocks: a 2 x 2 box mipmap (what engines build from a PNG) of the padded image,
    at every level, lies within the range of the stored texels of that block; the nearest-texel dilation it
    replaced (scipy's distance transform here) leaves the range by tens of codes at the same blocks."""
    from scipy import ndimage

    b = fixture_bake(128)
    res = b.res
    colours = (np.abs(np.sin(b.face[:, None] * np.array([0.37, 0.71, 1.13]))) * 255).astype(np.uint8)
    padded = b.image(colours).astype(float)
    stored = np.zeros((res, res), bool)
    stored.flat[b.texel] = True
    full = np.zeros((res * res, 3))
    full[b.texel] = colours
    assert np.array_equal(padded.reshape(-1, 3)[b.texel], colours)
    _, (r, c) = ndimage.distance_transform_edt(~stored, return_indices=True)
    nearest = full.reshape(res, res, 3)[r, c]

    def worst_excess(img):
        lo = np.where(stored[..., None], full.reshape(res, res, 3), np.inf)
        hi = np.where(stored[..., None], full.reshape(res, res, 3), -np.inf)
        worst = []
        for L in range(1, 8):
            n = res >> L
            img = img.reshape(n, 2, n, 2, 3).mean((1, 3))
            lo, hi = lo.reshape(n, 2, n, 2, 3).min((1, 3)), hi.reshape(n, 2, n, 2, 3).max((1, 3))
            has = np.isfinite(lo[..., 0])
            worst.append(float(np.maximum(lo - img, img - hi).max(-1)[has].max()))
        return np.array(worst)

    assert (worst_excess(padded) <= 0.5).all()            # rounding to 8 bits only
    assert worst_excess(nearest).max() > 20


def test_bake_of_fixture_labels_follow_faces_except_refined_nails():
    b = fixture_bake(128)
    face_label = fixture_model().face_labels[b.face]
    nail = FACE_LABEL_IDS["nail"]
    other = (face_label != nail) & (b.label != nail)
    assert np.array_equal(b.label[other], face_label[other])
    # The smooth nail plates stay on the nail faces' fingers' distal segments and overlap the labelled nails.
    refined = b.label == nail
    assert refined.any()
    assert (np.isin(b.fields["bone"][refined], [2, 5, 8, 11, 14])).all()
    overlap = (refined & (face_label == nail)).sum() / max((refined | (face_label == nail)).sum(), 1)
    assert overlap > 0.5


def test_bake_cache_round_trip_and_key(tmp_path):
    model = fixture_model()
    b, path = cached_bake(model, 64, tmp_path)
    assert path == tmp_path / "bake_64.npz" and path.is_file()
    again = load_bake(path)
    assert again.key == b.key == bake_key(model, 64)
    for name in ("texel", "face", "inside", "position", "normal", "label"):
        assert np.array_equal(getattr(again, name), getattr(b, name)), name
    for k, v in b.fields.items():
        assert np.array_equal(again.fields[k], v), k
    # A changed model gets a new key and a new bake.
    moved = model.replace(v_template=model.v_template * 1.01)
    assert bake_key(moved, 64) != b.key
    b2, _ = cached_bake(moved, 64, tmp_path)
    assert b2.key == bake_key(moved, 64)
    assert not np.allclose(b2.position, b.position[: len(b2.position)] if len(b2.position) <= len(b.position) else 0)


def test_save_bake_is_atomic_over_existing(tmp_path):
    b = fixture_bake(64)
    p = tmp_path / "bake_64.npz"
    save_bake(b, p)
    save_bake(b, p)
    assert [f.name for f in tmp_path.iterdir()] == ["bake_64.npz"]


def test_bake_rejects_bad_resolution_and_missing_uvs():
    from darthand.errors import InputError

    with pytest.raises(InputError, match="resolution"):
        bake(fixture_model(), 8)
    with pytest.raises(InputError, match="uvs"):
        bake(fixture_model(with_uvs=False), 64)
