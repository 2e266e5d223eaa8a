"""The rule functions on small arrays with known answers: closed meshes, exact distances, PNG structure, accessor
decoding, skeleton transforms, triangulation."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest
from package_parts import write_png

from darthand.model.layout import JOINT_NAMES, MANO_PARENTS
from darthand.validate.asset import Limits, Mesh, Skeleton, Skin
from darthand.validate.findings import PackageResult, Report, examples, finding
from darthand.validate.gltf_reader import Buffers, Malformed, TooLarge, node_parents, triangles
from darthand.accessories.collide import surface_distance, surface_trees
from darthand.validate.rules_mesh import check_mesh
from darthand.validate.rules_rig import check_skeleton, check_skin
from darthand.validate.rules_textures import check_png_chunks, png_info
from darthand.validate.usd_reader import triangulate

# A unit octahedron, outward winding: closed, manifold, consistent.
OCTA_V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
OCTA_F = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])


def rules(mesh: Mesh) -> set[str]:
    return {f.rule for f in check_mesh(mesh)}


def test_octahedron_is_clean_and_outward():
    a, b, c = (OCTA_V[OCTA_F[:, k]] for k in range(3))
    assert np.einsum("ij,ij->i", a, np.cross(b - a, c - a)).min() > 0      # every normal points away from 0
    assert rules(Mesh("/o", "hand", OCTA_V, OCTA_F)) == set()


def test_one_opening_is_the_forearm_two_are_a_hole():
    assert rules(Mesh("/o", "hand", OCTA_V, OCTA_F[1:])) == set()
    assert rules(Mesh("/o", "hand", OCTA_V, np.delete(OCTA_F, [0, 6], 0))) == {"mesh.open-boundary"}
    assert rules(Mesh("/o", "accessory", OCTA_V, np.delete(OCTA_F, [0, 6], 0))) == set()   # accessories may be open


def test_each_defect_fires_its_rule_only():
    flipped = OCTA_F.copy()
    flipped[3] = flipped[3, ::-1]
    assert rules(Mesh("/o", "hand", OCTA_V, flipped)) == {"mesh.winding"}
    assert rules(Mesh("/o", "hand", OCTA_V, np.vstack([OCTA_F, OCTA_F[2, [1, 2, 0]]]))) == {"mesh.duplicate-face"}
    fin_v = np.vstack([OCTA_V, [2, 2, 0]])
    assert "mesh.non-manifold-edge" in rules(Mesh("/o", "accessory", fin_v, np.vstack([OCTA_F, [0, 2, 6]])))
    nan_v = OCTA_V.copy()
    nan_v[5] = np.nan
    assert rules(Mesh("/o", "hand", nan_v, OCTA_F)) == {"mesh.nonfinite-point"}
    assert rules(Mesh("/o", "hand", OCTA_V, np.vstack([OCTA_F, [0, 1, 9]]))) == {"mesh.face-index"}


def test_degenerate_faces_repeated_and_collinear():
    v = np.vstack([OCTA_V, [[0.5, 0.5, 0.0]]])          # on the segment from vertex 0 to vertex 2
    found = check_mesh(Mesh("/o", "accessory", v, np.vstack([OCTA_F, [0, 0, 4], [0, 2, 6]])))
    (degenerate,) = [f for f in found if f.rule == "mesh.degenerate-face"]
    assert degenerate.message.endswith(": 8, 9")
    tiny = OCTA_V * 1e-4                                 # small but not degenerate: a 0.1 mm octahedron
    assert rules(Mesh("/o", "hand", tiny, OCTA_F)) == set()


def test_uv_seams_are_welded_by_position():
    """A mesh split along a seam (vertex 0 duplicated for half the faces, as glTF stores it) is still closed."""
    v = np.vstack([OCTA_V, OCTA_V[:1]])
    f = OCTA_F.copy()
    f[f[:, 0] == 0, 0] = 6
    f[4:][f[4:] == 0] = 6
    assert rules(Mesh("/o", "hand", v, f)) == set()


def test_uv_rules():
    uvs = np.array([[0, 0], [1, 1], [0.5, 0.5], [1.2, 0.5], [np.nan, 0]], float)
    used = np.array([[0, 1, 2]] * 8)
    assert rules(Mesh("/o", "hand", OCTA_V, OCTA_F, uvs, used)) == set()     # unused bad UVs are ignored
    assert rules(Mesh("/o", "hand", OCTA_V, OCTA_F, uvs, np.vstack([used[:7], [0, 3, 4]]))) == \
        {"mesh.uv-range", "mesh.uv-nonfinite"}
    assert rules(Mesh("/o", "hand", OCTA_V, OCTA_F, uvs, np.vstack([used[:7], [0, 1, 5]]))) == {"mesh.uv-index"}


# ------------------------------------------------------------------------------------------------ distances


def test_accessory_gap_of_a_shell_around_the_octahedron():
    """Points pushed out along the face normal of a face centre by h are h from the surface (the distance the
    acc.distance rule measures, with the trees it builds once per hand)."""
    a, b, c = (OCTA_V[OCTA_F[:, k]] for k in range(3))
    centres = (a + b + c) / 3
    normals = np.cross(b - a, c - a)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    for h in (0.001, 0.05):
        gap = surface_distance(centres + h * normals, OCTA_V, OCTA_F, surface_trees(OCTA_V[OCTA_F])).min()
        assert gap == pytest.approx(h, abs=1e-12)


# ------------------------------------------------------------------------------------------------ rig


def mano_skeleton(joints: np.ndarray) -> Skeleton:
    bind = np.tile(np.eye(4), (16, 1, 1))
    bind[:, :3, 3] = joints
    rest = bind.copy()
    rest[1:, :3, 3] -= joints[MANO_PARENTS[1:]]
    return Skeleton("/s", list(JOINT_NAMES), MANO_PARENTS.copy(), bind, rest)


def test_rigid_skeleton_is_clean_and_a_scaled_or_inconsistent_one_is_not():
    joints = np.random.default_rng(0).normal(scale=0.05, size=(16, 3))
    assert check_skeleton(mano_skeleton(joints)) == []
    rotated = mano_skeleton(joints)          # an oriented bind is rigid, but this one no longer matches the rests
    t = np.radians(5)
    rotated.bind[3, :2, :2] = [[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]]
    assert {f.rule for f in check_skeleton(rotated)} == {"rig.bind-rest-mismatch"}
    scaled = mano_skeleton(joints)
    scaled.bind[3, :3, :3] *= 1.1
    assert {f.rule for f in check_skeleton(scaled)} == {"rig.bind-transform", "rig.bind-rest-mismatch"}
    mirrored = mano_skeleton(joints)         # det -1: a reflection is not a rotation
    mirrored.bind[3, 0, 0] = -1
    assert "rig.bind-transform" in {f.rule for f in check_skeleton(mirrored)}


def test_weight_sum_tolerance_is_1e6():
    w = np.full((3, 4), 0.25)
    w[1, 0] += 5e-7
    w[2, 0] += 2e-6
    mesh = Mesh("/m", "hand", np.zeros((3, 3)), np.zeros((0, 3), np.int64),
                skin=Skin(np.zeros((3, 4), np.int64), w))
    (f,) = check_skin(mesh)
    assert f.rule == "rig.weights-sum" and f.message.startswith("points whose weights do not sum to 1: 2 ")


# ------------------------------------------------------------------------------------------------ PNG


def test_png_header_and_ending(tmp_path):
    data = write_png(tmp_path / "a.png", 64, 16, 0).read_bytes()
    info = png_info(data[:33], data[-12:])
    assert (info.width, info.height) == (64, 16)
    check_png_chunks(data)
    with pytest.raises(ValueError, match="IEND"):
        png_info(data[:33], data[:len(data) // 2][-12:])
    corrupt = bytearray(data)
    corrupt[data.index(b"IDAT") + 10] ^= 0x01
    png_info(bytes(corrupt[:33]), bytes(corrupt[-12:]))              # the cheap check cannot see it
    with pytest.raises(ValueError, match="CRC"):
        check_png_chunks(bytes(corrupt))


def test_png_header_crc_is_checked():
    ihdr = struct.pack(">IIBBBBB", 4, 4, 8, 2, 0, 0, 0)
    good = b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + ihdr + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr))
    tail = b"\x00\x00\x00\x00IEND\xaeB`\x82"
    assert png_info(good, tail).width == 4
    with pytest.raises(ValueError, match="CRC"):
        png_info(good[:20] + b"\x09" + good[21:], tail)


# ------------------------------------------------------------------------------------------------ glTF decoding


def buffers(doc: dict, blob: bytes, limits: Limits = Limits()) -> Buffers:
    doc = {"buffers": [{"byteLength": len(blob)}], **doc}
    return Buffers(doc, blob, None, None, limits)


def test_strided_normalised_and_sparse_accessors():
    xyz = np.arange(12, dtype=np.float32).reshape(4, 3)
    w = np.array([[255, 0, 0, 0], [128, 127, 0, 0], [0, 0, 0, 0], [1, 2, 3, 249]], np.uint8)
    interleaved = b"".join(xyz[i].tobytes() + w[i].tobytes() for i in range(4))        # stride 16
    sparse_idx = np.array([2], np.uint16).tobytes() + b"\0\0"
    sparse_val = np.array([7.0, 8.0, 9.0], np.float32).tobytes()
    blob = interleaved + sparse_idx + sparse_val
    doc = {"bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 64, "byteStride": 16},
                           {"buffer": 0, "byteOffset": 64, "byteLength": 4},
                           {"buffer": 0, "byteOffset": 68, "byteLength": 12}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
                         {"bufferView": 0, "byteOffset": 12, "componentType": 5121, "normalized": True,
                          "count": 4, "type": "VEC4"},
                         {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                          "sparse": {"count": 1, "indices": {"bufferView": 1, "componentType": 5123},
                                     "values": {"bufferView": 2}}}]}
    b = buffers(doc, blob)
    assert np.array_equal(b.accessor(0), xyz)
    assert np.allclose(b.accessor(1), w / 255.0)
    expected = xyz.copy()
    expected[2] = [7, 8, 9]
    assert np.array_equal(b.accessor(2), expected)


def test_bad_accessors_are_findings_not_crashes():
    blob = np.zeros(12, np.float32).tobytes()
    doc = {"bufferViews": [{"buffer": 0, "byteLength": 48}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 5, "type": "VEC3"},
                         {"bufferView": 0, "componentType": 5126, "count": 2 ** 40, "type": "VEC3"},
                         {"bufferView": 3, "componentType": 5126, "count": 1, "type": "VEC3"}]}
    b = buffers(doc, blob)
    with pytest.raises(Malformed, match="needs 60 bytes"):
        b.accessor(0)
    with pytest.raises(TooLarge):
        b.accessor(1)
    with pytest.raises(Malformed, match="does not exist"):
        b.accessor(2)


def test_node_cycles_and_strips():
    with pytest.raises(Malformed, match="cycle|more than one parent"):
        node_parents([{"children": [1]}, {"children": [0]}])
    assert node_parents([{"children": [2]}, {}, {"children": [1]}]) == [-1, 2, 0]
    strip = triangles(5, np.arange(5), 5)
    assert strip.tolist() == [[0, 1, 2], [1, 3, 2], [2, 3, 4]]         # alternate triangles keep the winding
    assert triangles(6, np.arange(4), 4).tolist() == [[0, 1, 2], [0, 2, 3]]
    assert triangles(1, None, 4) is None


def test_fan_triangulation_of_polygons():
    corners = triangulate(np.array([3, 4, 2]))
    assert corners.tolist() == [[0, 1, 2], [3, 4, 5], [3, 5, 6], [7, 8, 8]]


# ------------------------------------------------------------------------------------------------ report


def test_exit_codes_follow_the_worst_package():
    clean = PackageResult("a", "usd", [finding("rig.joint-names", "/s", "w")])
    bad = PackageResult("b", "glb", [finding("mesh.winding", "/m", "e")])
    unreadable = PackageResult("c", "usd", [finding("file.unreadable", "c", "x")])
    assert Report([clean]).exit_code == 0
    assert Report([clean, bad]).exit_code == 1
    assert Report([unreadable, bad]).exit_code == 2
    assert examples(np.arange(3)) == "0, 1, 2" and examples(np.arange(9)) == "0, 1, 2, 3, 4, ... (9 in all)"


def test_edge_problems_match_a_brute_force_count():
    """Fans (undirected edges of more than two faces) and flipped edges (a directed edge twice, on an edge of two
    faces) against counting every face's edges one by one."""
    import collections

    from darthand.validate.rules_mesh import edge_problems, weld

    rng = np.random.default_rng(5)
    for _ in range(20):
        faces = rng.integers(0, 12, size=(30, 3))
        faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
        directed = collections.Counter((int(f[k]), int(f[(k + 1) % 3])) for f in faces for k in range(3))
        undirected = collections.Counter()
        for (a, b), n in directed.items():
            undirected[min(a, b), max(a, b)] += n
        fans, flipped = edge_problems(faces)
        assert {tuple(e) for e in fans.tolist()} == {e for e, n in undirected.items() if n > 2}
        assert {tuple(e) for e in flipped.tolist()} == {
            e for e, n in directed.items() if n > 1 and undirected[min(e), max(e)] <= 2}
    points = rng.integers(0, 3, size=(200, 3)).astype(float)
    ids = weld(points)
    _, reference = np.unique(points, axis=0, return_inverse=True)
    assert np.array_equal(ids, reference.reshape(-1))
