"""Per-frame work done once, on less of the frame or in one pass, with the same bits as the plain computation: the
cotangent curvature's face-only structure (render/skin.mesh_structure, remembered per face array) against the
Laplacian assembled by scipy with np.add.at's sums, the model's coverage (render/dress.model_coverage, a compiled
pass) against np.isin, scipy's dilation and np.where, and the keypoints' nearest-vertex distances
(render/labels.keypoint_thickness) and the share of the sky a vertex's rays see (render/indirect._sky_share_kernel)
against numpy's broadcasts."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy import ndimage

from darthand.model.topology import boundary_loops
from darthand.render import skin
from darthand.render.labels import keypoint_thickness


def plain_curvature_radius(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """The curvature radius of skin.curvature_radius's definition, assembled the plain way: scipy's COO
    constructor for the cotangent matrix, np.add.at for areas and normals, the boundary walked per call."""
    v, f = np.asarray(v, np.float64), np.asarray(f, np.int64)
    n = len(v)
    rows, cols, vals = [], [], []
    area, normals = np.zeros(n), np.zeros((n, 3))
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        e1, e2 = v[f[:, j]] - v[f[:, i]], v[f[:, k]] - v[f[:, i]]
        cot = np.einsum("ij,ij->i", e1, e2) / np.maximum(np.linalg.norm(np.cross(e1, e2), axis=1), 1e-30)
        rows += [f[:, j], f[:, k]]
        cols += [f[:, k], f[:, j]]
        vals += [0.5 * cot, 0.5 * cot]
        np.add.at(area, f[:, i], 0.5 * np.linalg.norm(fn, axis=1) / 3)
    W = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    lap = (W @ v - np.asarray(W.sum(axis=1)) * v) / np.maximum(area, 1e-30)[:, None]
    np.add.at(normals, f.ravel(), np.repeat(fn, 3, axis=0))
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
    H = -0.5 * np.einsum("ij,ij->i", lap, normals)
    radius = np.where(H > 0, 1 / np.maximum(H, 1e-30), skin.FLAT_RADIUS)
    for loop in boundary_loops(f):
        radius[loop] = skin.FLAT_RADIUS
    return np.clip(radius, skin.MIN_RADIUS, skin.FLAT_RADIUS).astype(np.float32)


def _bumpy_ball(seed: int) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.01)
    rng = np.random.default_rng(seed)
    return ball.vertices * (1 + 0.2 * rng.random((len(ball.vertices), 1))), np.asarray(ball.faces, np.int64)


def _open_tube() -> tuple[np.ndarray, np.ndarray]:
    """A tube of 24 x 6 vertices without caps (two boundary loops), bulging in the middle."""
    phi = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    zs = np.linspace(-0.02, 0.02, 6)
    v = np.array([[(0.008 + 0.1 * (0.0004 - z * z)) * np.cos(a), 0.008 * np.sin(a), z] for z in zs for a in phi])
    f = [[j * 24 + i, j * 24 + (i + 1) % 24, (j + 1) * 24 + (i + 1) % 24] for j in range(5) for i in range(24)]
    f += [[j * 24 + i, (j + 1) * 24 + (i + 1) % 24, (j + 1) * 24 + i] for j in range(5) for i in range(24)]
    return v, np.array(f, np.int64)


@pytest.mark.parametrize("mesh", ["ball", "tube", "float32"])
def test_curvature_radius_is_the_plain_assembly_bit_for_bit(mesh):
    v, f = _open_tube() if mesh == "tube" else _bumpy_ball(3)
    if mesh == "float32":
        v = v.astype(np.float32)
    want = plain_curvature_radius(v, f)
    assert skin.curvature_radius(v, f).tobytes() == want.tobytes()
    assert skin.curvature_radius(v, f).tobytes() == want.tobytes()           # served from the remembered structure
    if mesh == "tube":
        assert (want[:24] == skin.FLAT_RADIUS).all() and (want[24:-24] < skin.FLAT_RADIUS).any()


def test_a_face_array_changed_in_place_is_not_served_the_old_structure():
    v, f = _bumpy_ball(5)
    first = skin.curvature_radius(v, f)
    f[:, [1, 2]] = f[:, [2, 1]].copy()                      # the same array object, every face turned over
    f[7] = f[8]                                             # and a repeated face: a non-manifold mesh
    got = skin.curvature_radius(v, f)
    assert got.tobytes() == plain_curvature_radius(v, f).tobytes()
    assert got.tobytes() != first.tobytes()
    assert not skin.mesh_structure(f, len(v)).exact                # three cotangents on an edge: scipy's own assembly


def test_the_structure_is_kept_per_face_array_contents():
    v, f = _bumpy_ball(1)
    n = len(v)
    assert skin.mesh_structure(f, n) is skin.mesh_structure(f.copy(), n)
    assert skin.mesh_structure(f, n) is not skin.mesh_structure(f[::-1].copy(), n)
    assert skin.mesh_structure(f, n) is not skin.mesh_structure(f, n + 1)


def test_vertices_no_face_uses_keep_the_plain_results():
    v, f = _bumpy_ball(2)
    v = np.concatenate([v, [[0.5, 0.5, 0.5]]])            # one vertex past the faces' last index
    assert skin.curvature_radius(v, f).tobytes() == plain_curvature_radius(v, f).tobytes()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_keypoint_thickness_is_numpys_nearest_distance(dtype):
    rng = np.random.default_rng(4)
    for trial in range(20):
        keypoints = rng.normal(size=(21, 3)) * 0.05
        vertices = (rng.normal(size=(500, 3)) * 0.05).astype(dtype)
        if trial == 3:
            vertices[40, 2] = np.nan                         # numpy's min: NaN everywhere
        d2 = ((keypoints[:, None, :] - vertices[None, :, :].astype(np.float64)) ** 2).sum(-1)
        want = np.sqrt(d2.min(axis=1))
        got = keypoint_thickness(keypoints, vertices, "mano")
        fingertips = slice(16, 21)                           # a tip takes its distal joint's (mano order)
        assert got[:16].tobytes() == want[:16].tobytes()
        assert np.array_equal(got[fingertips], want[[15, 3, 6, 12, 9]], equal_nan=True)


def test_model_coverage_is_the_plain_mask_of_the_models_pixels():
    """The coverage without the arm's and an object's pixels, edge pixels kept beside the model's, as np.isin,
    scipy's dilation and np.where give it (NaN and -0 coverage copied as they are)."""
    from types import SimpleNamespace

    from darthand.render.arm import ARM, ARM_END
    from darthand.render.dress import model_coverage

    surfaces = (SimpleNamespace(name="hand", role="hand"), SimpleNamespace(name=ARM, role="arm"),
                SimpleNamespace(name="ring", role="accessory"), SimpleNamespace(name=ARM_END, role="arm"),
                SimpleNamespace(name="mug", role="object"))
    left_out = [1, 3, 4]
    rng = np.random.default_rng(6)
    for k in range(60):
        shape = [(30, 41), (1, 17), (13, 1), (2, 2)][k % 4] if k >= 40 else (30, 41)     # one-pixel edges too
        geom = rng.integers(-1, 5, shape).astype(np.int8)
        geom[rng.random(geom.shape) < (0.2 * (k % 5))] = -1
        alpha = (rng.random(geom.shape) * (rng.random(geom.shape) < 0.8)).astype(np.float32)
        alpha[0, 0], alpha[-1, -1] = np.nan, -0.0
        model = (geom >= 0) & ~np.isin(geom, left_out)
        keep = model | ((geom < 0) & ndimage.binary_dilation(model, np.ones((3, 3), bool)))
        want = np.where(keep, alpha, 0).astype(np.float32)
        assert model_coverage(alpha, geom, surfaces).tobytes() == want.tobytes()
    assert model_coverage(alpha, geom, surfaces[:1]) is alpha                # nothing left out: alpha itself
    wide = geom.astype(np.int32)                    # a traced geom (int32) reads as the frame's int8 map does
    assert model_coverage(alpha, wide, surfaces).tobytes() == model_coverage(alpha, geom, surfaces).tobytes()


def test_sky_share_is_numpys_where_and_sums():
    """indirect._sky_share_kernel against VertexLight._environment_seen's definition in numpy, over dark and bright
    skies, all-blocked and open vertices, NaN and signed zeros."""
    from darthand.render.indirect import _sky_share_kernel

    rng = np.random.default_rng(8)
    for trial in range(60):
        k, n = int(rng.integers(1, 33)), int(rng.integers(0, 200))
        open_sky = (rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-3, 3, (n, 1))).astype(np.float32)
        sky = (rng.random((n * k, 3)) * 10.0 ** rng.integers(-14, 3, (n * k, 1))).astype(np.float32)
        blocked = rng.random(n * k) < rng.random()
        if n > 4:
            open_sky[rng.random(open_sky.shape) < 0.1] = -0.0
            open_sky[0, 0], sky[2 * k, 2] = np.nan, np.nan
            sky[3 * k:4 * k] = 0
            blocked[4 * k:5 * k] = True
        rays = sky.reshape(n, k, 3).astype(np.float64)
        seen = np.where(blocked.reshape(n, k, 1), 0.0, rays).sum(axis=1)
        total = rays.sum(axis=1)
        share = np.where(total > 1e-12, seen / np.maximum(total, 1e-12),
                         1.0 - blocked.reshape(n, k).mean(axis=1, keepdims=True))
        want = (np.maximum(open_sky, 0) * share).astype(np.float32)
        got = np.empty((n, 3), np.float32)
        _sky_share_kernel(open_sky, sky, blocked, k, got)
        assert got.tobytes() == want.tobytes(), trial


def test_builtin_maps_are_listed_again_when_the_folder_changes(tmp_path, monkeypatch):
    import os

    from darthand.render import environment

    monkeypatch.setattr(environment, "BUILTIN_DIR", tmp_path)
    for name in ("b", "a"):
        (tmp_path / f"{name}.exr").write_bytes(b"")
    (tmp_path / "notes.txt").write_text("not a map")
    os.utime(tmp_path, ns=(10**18, 10**18))
    assert environment.list_builtin() == ["a", "b"]
    (tmp_path / "c.exr").write_bytes(b"")
    os.utime(tmp_path, ns=(10**18 + 1, 10**18 + 1))      # as adding the file does (set: a tick may be coarser)
    assert environment.list_builtin() == ["a", "b", "c"] == sorted(p.stem for p in tmp_path.glob("*.exr"))
    environment.list_builtin().append("x")                  # a caller's list is its own
    assert environment.list_builtin() == ["a", "b", "c"]
