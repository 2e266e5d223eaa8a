"""Render-time Loop subdivision (render/subdivision.py): closed-form stencils on an octahedron, limit points against
repeated subdivision, a sphere-like mesh getting rounder, UVs kept inside their own charts across seams, and a
subdivided frame's labels, meshes and camera left as the model's."""

from __future__ import annotations

import numpy as np
import pytest

from darthand.errors import InputError
from darthand.render.api import Renderer
from darthand.render.dress import GeometryOptions, geometry_options
from darthand.render.subdivision import SubdivisionPlan, limit_matrix, loop_level
from testkit.mesh_distance import distance_to_mesh

OCTAHEDRON_V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
OCTAHEDRON_F = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])


def icosahedron() -> tuple[np.ndarray, np.ndarray]:
    """The unit icosahedron (12 vertices on the unit sphere, 20 outward-wound faces)."""
    p = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, p, 0], [1, p, 0], [-1, -p, 0], [1, -p, 0], [0, -1, p], [0, 1, p], [0, -1, -p], [0, 1, -p],
                  [p, 0, -1], [p, 0, 1], [-p, 0, -1], [-p, 0, 1]], float)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
                  [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
                  [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    return v / np.linalg.norm(v, axis=1, keepdims=True), f


def test_octahedron_level_matches_loop_stencils():
    M, faces = loop_level(OCTAHEDRON_F, 6)
    out = M @ OCTAHEDRON_V
    # Valence 4: beta = (5/8 - (3/8 + cos(pi/2)/4)^2) / 4 = 31/256; the four neighbours sum to zero.
    assert np.allclose(out[:6], OCTAHEDRON_V * (1 - 4 * 31 / 256), atol=1e-15)
    # Edge (0, 2) between faces (0, 2, 4) and (2, 0, 5): 3/8 (v0 + v2) + 1/8 (v4 + v5).
    edge_vertex = 3 / 8 * (OCTAHEDRON_V[0] + OCTAHEDRON_V[2]) + 1 / 8 * (OCTAHEDRON_V[4] + OCTAHEDRON_V[5])
    assert np.isclose(np.abs(out[6:] - edge_vertex).sum(axis=1), 0).sum() == 1
    assert M.shape == (18, 6) and faces.shape == (32, 3) and np.allclose(M.sum(axis=1), 1)


def test_limit_points_are_where_repeated_subdivision_goes():
    v, f = icosahedron()
    v = v * np.array([1.0, 0.6, 1.3]) + 0.05 * np.sin(7 * v)        # irregular: no symmetry does the work
    limit = limit_matrix(f, len(v)) @ v
    M, faces = loop_level(f, len(v))
    points = M @ v
    for _ in range(6):
        step, faces = loop_level(faces, len(points))
        points = step @ points
    # Old vertices keep their indices through the levels; six levels bring them within 1e-4 of the limit.
    assert np.abs(points[:len(v)] - limit).max() < 1e-4
    assert np.abs(limit - v).max() > 1e-2


def sphere_deviation(v: np.ndarray, f: np.ndarray) -> float:
    """Largest relative deviation from the mean radius over points spread on the triangles."""
    w = np.array([(a, b, 1 - a - b) for a in np.linspace(0, 1, 7) for b in np.linspace(0, 1, 7) if a + b <= 1])
    pts = np.einsum("sk,fkc->fsc", w, v[f]).reshape(-1, 3)
    r = np.linalg.norm(pts, axis=1)
    return float(np.abs(r / r.mean() - 1).max())


def test_a_sphere_like_mesh_gets_rounder():
    v, f = icosahedron()
    errors = [sphere_deviation(v, f)]
    for level in (1, 2):
        plan = SubdivisionPlan.build(f, len(v), level)
        errors.append(sphere_deviation(plan.positions(v).astype(np.float64), plan.faces))
    assert errors[0] > 0.1 and errors[1] < errors[0] / 3 and errors[2] < errors[1] / 2, errors


def cube_with_seams() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A unit cube (8 vertices, 12 faces) whose six sides are six UV islands in a 3 x 2 atlas (every cube edge a
    seam): (vertices, faces, uvs (24, 2), faces_uv)."""
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    faces, faces_uv, uvs = [], [], []
    for k, q in enumerate(quads):
        u0, v0 = (k % 3) / 3, (k // 3) / 2
        base = len(uvs)
        uvs += [[u0 + 0.02, v0 + 0.02], [u0 + 0.31, v0 + 0.02], [u0 + 0.31, v0 + 0.48], [u0 + 0.02, v0 + 0.48]]
        faces += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
        faces_uv += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return v, np.array(faces), np.array(uvs), np.array(faces_uv)


def barycentric(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(..., 3) barycentric coordinates of 2D points p (..., 2) in triangles tri (..., 3, 2)."""
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    d = (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (c[..., 0] - a[..., 0]) * (b[..., 1] - a[..., 1])
    l1 = ((p[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (c[..., 0] - a[..., 0]) * (p[..., 1] - a[..., 1])) / d
    l2 = ((b[..., 0] - a[..., 0]) * (p[..., 1] - a[..., 1]) - (p[..., 0] - a[..., 0]) * (b[..., 1] - a[..., 1])) / d
    return np.stack([1 - l1 - l2, l1, l2], -1)


def assert_uvs_stay_in_their_charts(faces_uv, uvs, plan: SubdivisionPlan, level: int) -> None:
    """Every subdivided face's UV triangle lies inside its control face's, with 4^-level of its area: no texel
    is stretched across a seam."""
    sub_uv = plan.uv_matrix @ uvs
    child = sub_uv[plan.faces_uv]                                  # (F', 3, 2)
    parent = uvs[faces_uv[plan.parent]]                            # (F', 3, 2)
    bary = barycentric(child, parent[:, None])
    assert bary.min() > -1e-9 and bary.max() < 1 + 1e-9
    def area(t):
        e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
        return np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    assert np.allclose(area(child), area(parent) / 4 ** level, rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("level", [1, 2])
def test_uv_seams_kept_on_a_cube(level):
    v, f, uvs, fuv = cube_with_seams()
    plan = SubdivisionPlan.build(f, len(v), level, fuv, len(uvs))
    assert_uvs_stay_in_their_charts(fuv, uvs, plan, level)
    if level == 1:      # 8 vertices + 18 edges; 24 UVs + 6 islands x 5 UV edges (the seams are not shared)
        assert plan.matrix.shape == (26, 8) and plan.uv_matrix.shape == (54, 24)


def test_uv_seams_kept_on_the_hand(hand):
    plan = SubdivisionPlan.build(hand.faces, hand.num_vertices, 1, hand.faces_uv, len(hand.uvs))
    assert_uvs_stay_in_their_charts(hand.faces_uv, hand.uvs, plan, 1)


def test_the_limit_surface_stays_near_the_hand(hand):
    """The subdivided hand is within a few millimetres of its control mesh (Loop's limit lies inside convex parts)
    and it moved: the outline is not the control mesh's."""
    for level in (1, 2):
        plan = SubdivisionPlan.build(hand.faces, hand.num_vertices, level)
        distance = distance_to_mesh(plan.positions(hand.v_template).astype(np.float64), hand.v_template, hand.faces)
        assert 1e-4 < distance.max() < 4e-3, (level, distance.max())


def test_options_refuse_bad_levels():
    assert GeometryOptions().is_default and GeometryOptions().to_json() == {}
    assert geometry_options({"subdivision": 1}).to_json() == {"subdivision": 1}
    for bad in ({"subdivision": 3}, {"subdivision": -1}, {"arm": 0.001}, {"smooth": 1}):
        with pytest.raises(InputError):
            geometry_options(bad)


@pytest.mark.parametrize("pose, camera", [("fist", "three_quarter"), ("point", "palmar"), ("spread", "radial")])
def test_subdivided_frame_keeps_labels_camera_and_mesh(assets, pose, camera):
    renderer = Renderer(assets, threads=1)
    plain = renderer.render(pose, camera=camera, width=128, height=128)
    smooth = renderer.render(pose, camera=camera, width=128, height=128, subdivision=1)
    a, b = dict(plain.labels), dict(smooth.labels)
    assert b["render"].pop("geometry") == {"subdivision": 1}
    # Everything but what the drawn outline decides (the mask's bbox and coverage); visibility is traced against
    # the model's own faces.
    assert {k for k in a if a[k] != b[k]} <= {"bbox", "coverage"}
    assert np.array_equal(smooth.subject.hand_vertices, plain.subject.hand.vertices)
    assert len(smooth.subject.hand.vertices) > 3 * len(plain.subject.hand.vertices)
    # The image is the same hand, its outline moved by less than the limit surface's distance (about a pixel here).
    overlap = (plain.alpha > 0.5) & (smooth.alpha > 0.5)
    assert overlap.sum() > 0.95 * (plain.alpha > 0.5).sum()


def test_geometry_enters_the_frame_digest_only_when_on():
    """Resume keys frames by their digest: a run with subdivision or the arm renders its frames again, a run with
    both off keeps the digests it had before the options existed."""
    from darthand.dataset.frames import job_digest

    job = {"index": 3, "side": "right", "pose": "fist"}
    base = {"size": 64, "samples": 4, "aa_shading": "triangle", "shading": None, "maps": ()}
    plain = job_digest(job, base)
    assert job_digest(job, {**base, "geometry": {}}) == plain
    digests = {job_digest(job, {**base, "geometry": geometry_options(g).to_json()})
               for g in ({"subdivision": 1}, {"subdivision": 2}, {"arm": 0.3}, {"subdivision": 1, "arm": 0.3})}
    assert len(digests) == 4 and plain not in digests


def test_subdivided_faces_keep_their_parts(assets):
    """Per-face data follow each control face to its children (face f's are 4^k f .. 4^k (f + 1) - 1, the model's
    wrist faces scaled alike): the parts map of a subdivided frame is the plain frame's but for its moved outline."""
    renderer = Renderer(assets, threads=1)
    plain = renderer.render("spread", camera="dorsal", width=96, height=96, maps=("parts",)).maps["parts"]
    for level in (1, 2):
        smooth = renderer.render("spread", camera="dorsal", width=96, height=96, maps=("parts",),
                                 subdivision=level).maps["parts"]
        both = (plain > 0) & (smooth > 0)
        assert (plain[both] != smooth[both]).mean() < 0.03, level
        assert set(np.unique(smooth)) == set(np.unique(plain))


def test_a_glove_is_subdivided_with_the_skin(hand, texture_files):
    """A skinned accessory lies a fraction of a millimetre off the skin: subdivided with it (the same linear map of
    nearly the same surface), the skin stays under it; subdividing the skin alone pushes its concave parts through
    (177 skin pixels here)."""
    from darthand.accessories.loader import Accessory
    from darthand.model.topology import vertex_normals
    from darthand.render.assets import HandAssets

    offset = hand.v_template + 0.0005 * vertex_normals(hand.v_template, hand.faces)
    glove = Accessory(id="glove_test", vertices=offset, faces=hand.faces, weights=hand.weights,
                      posedirs=hand.posedirs, material={"base_color": (0.1, 0.2, 0.8, 1.0)}, kind="glove")
    assets = HandAssets(hand, {texture_files.id: texture_files}, texture_files.id, {glove.id: glove}, "open+wrist")
    renderer = Renderer(assets, threads=1)
    frames = {level: renderer.render("fist", camera="palmar", width=256, height=256, accessory="glove_test",
                                     subdivision=level) for level in (0, 1)}
    skin = {level: int((frame.geom == 0).sum()) for level, frame in frames.items()}
    assert skin[1] <= skin[0] + 5, skin
    assert len(frames[1].subject.accessory.faces) == 4 * len(hand.faces)


def test_dressed_frames_are_deterministic(assets, hand, texture_files, ring):
    """The same frame from a fresh renderer and source, with subdivision and the arm: the same bytes."""
    from darthand.render.assets import HandAssets

    again = HandAssets(hand, {texture_files.id: texture_files}, texture_files.id, {ring.id: ring}, "open+wrist")
    a, b = (Renderer(src, threads=1).render("ok", accessory="ring_test", width=96, height=96, subdivision=2, arm=0.3)
            for src in (assets, again))
    assert np.array_equal(a.rgba, b.rgba) and a.labels == b.labels
