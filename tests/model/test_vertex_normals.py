"""Vertex normals (model/topology.vertex_normals, a compiled pass).

Truth: closed-form normals of an octahedron (each vertex's faces are symmetric about it, so its area-weighted normal
is its own direction), a float64 scatter-add written here, and the sparse incidence product the compiled pass
replaced, which it must match to the bit (the renderer's frames did not change with it).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from darthand.model.forward import forward
from darthand.model.load import TEMPLATE_DIR, load_model
from darthand.model.topology import vertex_normals
from darthand.model.wrist import add_wrist

OCTAHEDRON_V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float64)
OCTAHEDRON_F = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])


def scatter_normals(v: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted normals in float64 by np.add.at."""
    v = v.astype(np.float64)
    n = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    out = np.zeros_like(v)
    for k in range(3):
        np.add.at(out, faces[:, k], n)
    length = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, length, out=np.zeros_like(out), where=length > 0)


def incidence_normals(v: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The implementation the compiled pass replaced: (V, F) incidence matrix times the face cross products."""
    faces = faces.astype(np.int32)
    inc = sp.csr_matrix((np.ones(faces.size, np.float32), (faces.reshape(-1), np.repeat(np.arange(len(faces)), 3))),
                        shape=(len(v), len(faces)))
    n = inc @ np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0).astype(v.dtype, copy=False)


@pytest.fixture(scope="module")
def hand():
    if not (TEMPLATE_DIR / "open_right.npz").is_file():
        pytest.skip("assets_src/template/open_right.npz is not in this checkout")
    return add_wrist(load_model("open"))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_octahedron_vertices_point_outward(dtype):
    n = vertex_normals(OCTAHEDRON_V.astype(dtype), OCTAHEDRON_F)
    assert n.dtype == dtype
    np.testing.assert_allclose(n, OCTAHEDRON_V, atol=1e-7)


def test_unused_vertex_is_zero_and_integer_vertices_become_float():
    v = np.vstack([OCTAHEDRON_V, [[5, 5, 5]]]).astype(np.int64)
    n = vertex_normals(v, OCTAHEDRON_F)
    assert n.dtype == np.float64
    np.testing.assert_array_equal(n[-1], 0)
    np.testing.assert_allclose(n[:-1], OCTAHEDRON_V, atol=1e-12)


def test_degenerate_faces_add_nothing():
    faces = np.vstack([OCTAHEDRON_F, [[0, 0, 2], [4, 4, 4]]])
    np.testing.assert_array_equal(vertex_normals(OCTAHEDRON_V, faces), vertex_normals(OCTAHEDRON_V, OCTAHEDRON_F))


@pytest.mark.parametrize("index", [6, -1])
def test_face_index_outside_the_vertices_is_an_error(index):
    with pytest.raises(IndexError, match="outside the 6 vertices"):
        vertex_normals(OCTAHEDRON_V, np.vstack([OCTAHEDRON_F, [[0, 1, index]]]))


def test_no_faces_gives_zero_normals():
    np.testing.assert_array_equal(vertex_normals(OCTAHEDRON_V, np.zeros((0, 3), np.int64)), 0)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_posed_hand_matches_scatter_and_the_incidence_product_bit_for_bit(hand, dtype):
    rng = np.random.default_rng(7)
    for pose in rng.normal(0, 0.5, (6, 48)):
        v = forward(hand, pose[None], dtype=dtype).vertices[0]
        n = vertex_normals(v, hand.faces)
        assert n.dtype == dtype
        np.testing.assert_allclose(n, scatter_normals(v, hand.faces), atol=2e-6 if dtype == np.float32 else 1e-12)
        np.testing.assert_array_equal(n, incidence_normals(v, hand.faces))
