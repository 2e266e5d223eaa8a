"""Rasterised camera visibility (render/raster.py) against closed forms and against Embree: which pixel centres a
square facing the camera covers (its edges and its diagonal through sample positions: each covered once, by the
top-left rule), the barycentrics and depth of a slanted triangle against the ray-plane intersection solved here,
a nearer square hiding a farther one, faces reaching behind the camera clipped at its near limit (a floor in
closed form, a hand's face against Embree), a posed hand with a ring and its arm against Embree's camera rays, and
the fallback to Embree when a vertex is not finite."""

from __future__ import annotations

import numpy as np
import pytest
from render_scenes import subject, surface

from darthand.render import raster, trace
from darthand.render.api import Renderer
from darthand.render.camera import Camera, look_at
from darthand.render.scene import Scene
from darthand.render.trace import Context

ARM_M = 0.3


@pytest.fixture
def rasterising(monkeypatch):
    monkeypatch.setattr(raster, "ENABLED", True)


def context(subj, cam) -> Context:
    return Context(Scene(subj), cam, [], np.zeros(3, np.float32))


def embree_hits(ctx, uv):
    raster.ENABLED, before = False, raster.ENABLED
    try:
        return trace.intersect_samples(ctx, uv)
    finally:
        raster.ENABLED = before


def down_camera(size=64, focal=32.0, height=2.0) -> Camera:
    """Looking down -z from (0, 0, height), focal length `focal` pixels, principal point at the image centre:
    world (x, y, 0) projects to (size / 2 + focal x / height, size / 2 - focal y / height) (+y up in the image),
    exactly in binary for the numbers used here."""
    return look_at((0, 0, height), (0, 0, 0), (0, 1, 0), width=size, height=size, focal_px=focal)


def square(x0, x1, y0, y1, z=0.0, diagonal_first=True):
    """Two triangles over [x0, x1] x [y0, y1] at height z, sharing the diagonal (x0, y0) - (x1, y1)."""
    v = [(x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)]
    return surface(v, [[0, 1, 2], [0, 2, 3]] if diagonal_first else [[1, 2, 3], [1, 3, 0]])


def test_a_square_facing_the_camera_covers_the_pixel_centres_inside_its_projection(rasterising):
    cam = down_camera()
    # Image x = 32 + 16 X, image y = 32 - 16 Y: the square's edges at 22.2, 45.1 (columns) and 17.6, 40.9 (rows).
    subj = subject(square(-0.6125, 0.81875, -0.55625, 0.9))
    uv = trace.pixel_centres(0, 64, 0, 64)
    hits = trace.intersect_samples(context(subj, cam), uv)
    inside = (uv[:, 0] > 32 + 16 * -0.6125) & (uv[:, 0] < 32 + 16 * 0.81875) & \
             (uv[:, 1] > 32 - 16 * 0.9) & (uv[:, 1] < 32 - 16 * -0.55625)
    assert np.array_equal(hits.geom >= 0, inside) and inside.sum() == 23 * 23
    assert np.allclose(hits.depth[inside], 2.0, rtol=1e-6) and np.isinf(hits.depth[~inside]).all()
    assert set(np.unique(hits.prim[inside])) == {0, 1}


def test_samples_on_edges_and_on_the_shared_diagonal_are_covered_once(rasterising):
    """Edges through pixel centres: the top-left rule keeps the left and top ones, drops the right and bottom
    ones; the diagonal through pixel centres goes to exactly one of its two triangles."""
    cam = down_camera()
    x0, x1 = (24.5 - 32) / 16, (40.5 - 32) / 16          # columns 24.5 .. 40.5: both edges through centres
    y1, y0 = (32 - 8.5) / 16, (32 - 24.5) / 16            # rows 8.5 (top) .. 24.5 (bottom)
    uv = trace.pixel_centres(0, 64, 0, 64)
    expected = (uv[:, 0] >= 24.5) & (uv[:, 0] < 40.5) & (uv[:, 1] >= 8.5) & (uv[:, 1] < 24.5)
    for diagonal_first in (True, False):
        whole = square(x0, x1, y0, y1, diagonal_first=diagonal_first)
        hits = trace.intersect_samples(context(subject(whole), cam), uv)
        assert np.array_equal(hits.geom >= 0, expected)
        alone = [trace.intersect_samples(context(subject(surface(whole.vertices, whole.faces[[k]])), cam), uv)
                 for k in (0, 1)]
        covered = [a.geom >= 0 for a in alone]
        assert not (covered[0] & covered[1]).any() and np.array_equal(covered[0] | covered[1], expected)
        # the diagonal: (24.5, 24.5) - (40.5, 8.5) through 15 covered centres, or (40.5, 24.5) - (24.5, 8.5)
        # through 16
        on_diagonal = expected & ((uv[:, 0] + uv[:, 1] == 49) if diagonal_first else (uv[:, 0] - uv[:, 1] == 16))
        assert on_diagonal.sum() == (15 if diagonal_first else 16) and (hits.geom[on_diagonal] == 0).all()


def test_a_slanted_triangle_gives_the_ray_plane_intersection():
    cam = look_at((0.05, -0.4, 0.3), (0, 0, 0), (0, 0, 1), width=96, height=96, fov_deg=35)
    corners = np.array([[-0.11, -0.03, -0.05], [0.09, -0.06, 0.02], [0.01, 0.12, 0.08]], np.float32)
    subj = subject(surface(corners, [[0, 1, 2]]))
    uv = trace.pixel_centres(0, 96, 0, 96)
    raster.ENABLED, before = True, raster.ENABLED
    try:
        hits = trace.intersect_samples(context(subj, cam), uv)
    finally:
        raster.ENABLED = before
    on = hits.geom >= 0
    assert on.sum() > 500
    # The ray o + t d (d from camera.py's float64 inverse of K, camera z = 1) against the plane of the corners.
    d = cam.directions(uv[on])
    o = cam.centre
    V = corners.astype(np.float64)
    A = np.stack([np.broadcast_to(V[1] - V[0], d.shape), np.broadcast_to(V[2] - V[0], d.shape), -d], axis=2)
    u, v, t = np.linalg.solve(A, (o - V[0])[None].repeat(len(d), 0)[..., None])[..., 0].T
    assert np.abs(hits.u[on] - u).max() < 1e-5 and np.abs(hits.v[on] - v).max() < 1e-5
    assert np.abs(hits.depth[on] / t - 1).max() < 1e-6
    assert (u >= -1e-6).all() and (v >= -1e-6).all() and (u + v <= 1 + 1e-6).all()
    assert np.allclose(t, cam.to_camera(o[None] + t[:, None] * d)[:, 2], rtol=1e-9)    # t is the camera z


def test_a_nearer_square_hides_a_farther_one(rasterising):
    cam = down_camera()
    far = square(-1.0, 0.5, -1.0, 0.5, z=0.0)
    near = square(-0.25, 1.0, -0.25, 1.0, z=0.5)             # 1.5 m from the camera: x = 32 + 21.33 X
    uv = trace.pixel_centres(0, 64, 0, 64)
    for order in ((far, near), (near, far)):
        hits = trace.intersect_samples(context(subject(*order), cam), uv)
        in_near = (np.abs(uv[:, 0] - (32 + 32 / 1.5 * 0.375)) < 32 / 1.5 * 0.625) & \
                  (np.abs(uv[:, 1] - (32 - 32 / 1.5 * 0.375)) < 32 / 1.5 * 0.625)
        in_far = (np.abs(uv[:, 0] - (32 - 16 * 0.25)) < 16 * 0.75) & (np.abs(uv[:, 1] - (32 + 16 * 0.25)) < 16 * 0.75)
        near_index = order.index(near)
        assert np.array_equal(hits.geom == near_index, in_near)
        assert np.array_equal(hits.geom == 1 - near_index, in_far & ~in_near)
        assert np.allclose(hits.depth[in_near], 1.5, rtol=1e-6)


def test_faces_turned_away_are_seen_wherever_nothing_nearer_hides_them(rasterising):
    """Faces turned away from the camera are drawn last, and skipped where the samples around them are already
    nearer (raster._hidden_depth): a square turned away in front of one facing the camera, wholly inside its
    outline, is seen; one behind it is seen only outside it, and a small one wholly behind it is not seen; in
    closed form, on pixel centres and on sub-samples."""
    from darthand.render.aa import sample_offsets

    cam = down_camera()

    def away(sq):                        # the same square wound the other way: its normal points down, away
        return surface(sq.vertices, sq.faces[:, ::-1])

    squares = [((-1.0, 0.5, -1.0, 0.5), 0.0, False), ((-0.25, 1.0, -0.25, 1.0), -0.5, True),
               ((-0.6, -0.2, -0.6, -0.2), -0.5, True), ((-0.55, -0.1, -0.55, 0.1), 0.5, True)]
    surfaces = [away(square(*box, z=z)) if turned else square(*box, z=z) for box, z, turned in squares]
    centres = trace.pixel_centres(0, 64, 0, 64)
    for uv in (centres, (centres[:, None, :] + sample_offsets(4)[None]).reshape(-1, 2)):
        hits = trace.intersect_samples(context(subject(*surfaces), cam), uv)
        expected, nearest = np.full(len(uv), -1), np.full(len(uv), np.inf)
        for k, ((x0, x1, y0, y1), z, _) in enumerate(squares):
            focal = 32 / (2.0 - z)                                  # image x = 32 + focal X, y = 32 - focal Y
            inside = (uv[:, 0] > 32 + focal * x0) & (uv[:, 0] < 32 + focal * x1) & \
                     (uv[:, 1] > 32 - focal * y1) & (uv[:, 1] < 32 - focal * y0)
            wins = inside & (2.0 - z < nearest)
            expected[wins], nearest[wins] = k, 2.0 - z
        assert {0, 1, 3} <= set(np.unique(expected)) and not (expected == 2).any()
        assert np.array_equal(hits.geom, expected)
        assert np.allclose(hits.depth[expected >= 0], nearest[expected >= 0], rtol=1e-6)


def test_a_posed_hand_with_a_ring_and_its_arm_as_embree_sees_it(assets, ring):
    """Every pixel centre and the four sub-samples of every pixel of a 128^2 frame: the same surface and face as
    Embree's camera rays on 99.9 % of them; where they agree, u, v and relative depth within 1e-4 (on 99.9 %: on
    faces seen edge-on Embree's float32 barycentrics are off by up to 1e-3, which the float64 solve below shows)
    and the rasteriser's u, v within 1e-5 of the ray-plane intersection solved here in float64."""
    from darthand.render.aa import sample_offsets

    frame = Renderer(assets, 1).render("fist", camera="three_quarter", width=128, height=128, accessory=ring.id,
                                       arm=ARM_M, labels=False, samples=1)
    subj, cam = frame.subject, frame.camera
    ctx = context(subj, cam)
    assert [s.role for s in subj.surfaces] == ["hand", "accessory", "arm", "cap"] and ctx.scene.rigid
    centres = trace.pixel_centres(0, 128, 0, 128)
    for uv in (centres, (centres[:, None, :] + sample_offsets(4)[None]).reshape(-1, 2)):
        ref = embree_hits(ctx, uv)
        raster.ENABLED, before = True, raster.ENABLED
        try:
            hits = trace.intersect_samples(ctx, uv)
        finally:
            raster.ENABLED = before
        assert np.array_equal(hits.directions, ref.directions)
        agree = (hits.geom == ref.geom) & ((hits.prim == ref.prim) | (ref.geom < 0))
        assert agree.mean() >= 0.999
        on = agree & (ref.geom >= 0)
        assert {0, 1, 2} <= set(np.unique(ref.geom[on]))             # the hand, the ring and the arm are seen
        du, dv = np.abs(hits.u[on] - ref.u[on]), np.abs(hits.v[on] - ref.v[on])
        assert (du <= 1e-4).mean() >= 0.999 and (dv <= 1e-4).mean() >= 0.999
        assert (np.abs(hits.depth[on] / ref.depth[on] - 1) <= 1e-4).all()
        u, v = solved_barycentrics(ctx, hits, on)
        assert np.abs(hits.u[on] - u).max() < 1e-5 and np.abs(hits.v[on] - v).max() < 1e-5


def solved_barycentrics(ctx, hits, on):
    """(u, v) of the hits `on` by a float64 solve of each ray against its face's corners (world vertices)."""
    u, v = np.empty(on.sum()), np.empty(on.sum())
    o = ctx.camera.centre.astype(np.float32).astype(np.float64)
    for g, s in enumerate(ctx.scene.surfaces):
        mine = hits.geom[on] == g
        corners = s.vertices[s.faces[hits.prim[on][mine]]].astype(np.float64)        # (M, 3, 3)
        d = hits.directions[:, on][:, mine].T.astype(np.float64)
        A = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0], -d], axis=2)
        solved = np.linalg.solve(A, (o[None] - corners[:, 0])[..., None])[..., 0]
        u[mine], v[mine] = solved[:, 0], solved[:, 1]
    return u, v


def test_a_floor_reaching_behind_the_camera_is_clipped_at_the_near_limit(rasterising):
    """A floor 0.1 m below a camera (camera frame = world), from 1 m behind it to 5 m ahead: its triangles have
    corners behind the camera, so they are clipped; a ray (x, y, 1) meets it where y > 0.1 / 5 and |x| 0.1 / y <
    0.6, at depth 0.1 / y."""
    K = np.array([[40.0, 0, 32], [0, 40.0, 32], [0, 0, 1]])
    cam = Camera(K, np.eye(3), np.zeros(3), 64, 64)
    floor = surface([(-0.6, 0.1, -1.0), (0.6, 0.1, -1.0), (0.6, 0.1, 5.0), (-0.6, 0.1, 5.0)], [[0, 1, 2], [0, 2, 3]])
    subj = subject(floor)
    uv = trace.pixel_centres(0, 64, 0, 64)
    hits = trace.intersect_samples(context(subj, cam), uv)
    x, y = (uv[:, 0] - 32) / 40, (uv[:, 1] - 32) / 40
    with np.errstate(divide="ignore"):
        reach = np.where(y > 0, 0.1 / y, np.inf)
    on = (y > 0.02) & (np.abs(x) * reach < 0.6)
    clear = (np.abs(y - 0.02) > 1e-6) & (np.abs(np.abs(x) * reach - 0.6) > 1e-6)
    assert on.sum() > 300 and np.array_equal((hits.geom >= 0)[clear], on[clear])
    assert np.allclose(hits.depth[on], reach[on], rtol=1e-6)
    ref = embree_hits(context(subj, cam), uv)
    assert np.array_equal(hits.geom, ref.geom) and np.array_equal(hits.prim, ref.prim)


def test_a_hand_face_reaching_behind_the_camera_as_embree_sees_it(assets, rasterising):
    frame = Renderer(assets, 1).render("fist", camera="three_quarter", width=64, height=64, labels=False,
                                       samples=1)
    cam, hand = frame.camera, frame.subject.hand
    behind = (cam.centre - 0.1 * cam.R[2] + 0.02 * cam.R[1]).astype(np.float32)
    subj = subject(surface(np.vstack([hand.vertices, behind[None]]),
                           np.vstack([hand.faces, [[0, 1, len(hand.vertices)]]])))
    ctx = context(subj, cam)
    uv = trace.pixel_centres(0, 64, 0, 64)
    hits, ref = trace.intersect_samples(ctx, uv), embree_hits(ctx, uv)
    on_new = (ref.geom == 0) & (ref.prim == len(hand.faces))
    assert on_new.sum() > 20                                       # the clipped face is seen
    agree = (hits.geom == ref.geom) & (hits.prim == ref.prim)
    assert agree.mean() >= 0.999 and agree[on_new].all()
    assert np.abs(hits.depth[agree & (ref.geom >= 0)] / ref.depth[agree & (ref.geom >= 0)] - 1).max() < 1e-4


def test_a_vertex_that_is_not_finite_sends_the_rays_to_embree(assets, rasterising):
    frame = Renderer(assets, 1).render("fist", camera="three_quarter", width=64, height=64, labels=False,
                                       samples=1)
    cam, hand = frame.camera, frame.subject.hand
    subj = subject(surface(np.vstack([hand.vertices, [[np.nan, 0, 0]]]),
                           np.vstack([hand.faces, [[0, 1, len(hand.vertices)]]])))
    ctx = context(subj, cam)
    uv = trace.pixel_centres(0, 64, 0, 64)
    directions = np.ascontiguousarray(ctx.directions(uv), np.float32)
    assert raster.camera_hits(ctx.scene, cam, uv, directions) is None
    assert raster.camera_hits(context(frame.subject, cam).scene, cam, uv, directions) is not None
    hits, ref = trace.intersect_samples(ctx, uv), embree_hits(ctx, uv)
    for k in ("geom", "prim", "u", "v", "depth", "directions"):
        assert np.array_equal(getattr(hits, k), getattr(ref, k)), k
    assert (hits.geom >= 0).any()


def test_switched_off_the_camera_rays_are_embrees(assets, monkeypatch):
    frame = Renderer(assets, 1).render("fist", camera="three_quarter", width=48, height=48, labels=False, samples=1)
    ctx = context(frame.subject, frame.camera)
    uv = trace.pixel_centres(0, 48, 0, 48)
    monkeypatch.setattr(raster, "ENABLED", False)
    assert raster.camera_hits(ctx.scene, ctx.camera, uv, np.ascontiguousarray(ctx.directions(uv))) is None


def test_a_frame_rasterised_has_the_same_labels_and_nearly_the_same_image(assets, ring, monkeypatch):
    """A whole frame (primary samples, edge sub-samples, shading) both ways: the labels are the model's and the
    labels' own rays (byte-identical), the image differs only where a sample on a face's edge went to the neighbour
    face (a different texel and normal there)."""
    import json

    def frame():
        return Renderer(assets, 1).render("fist", camera="three_quarter", width=96, height=96, accessory=ring.id,
                                          arm=ARM_M, samples=4)

    monkeypatch.setattr(raster, "ENABLED", False)
    embree = frame()
    monkeypatch.setattr(raster, "ENABLED", True)
    ours = frame()
    assert ours.stats["rasterised"] == ours.stats["rays"] > 0 and "rasterised" not in embree.stats
    assert json.dumps(ours.labels, sort_keys=True) == json.dumps(embree.labels, sort_keys=True)
    assert np.array_equal(ours.geom, embree.geom) or (ours.geom != embree.geom).mean() < 1e-3
    differ = np.abs(ours.rgba.astype(int) - embree.rgba.astype(int)).max(axis=2) > 0
    assert differ.mean() < 2e-3


def grid_by_numpy(uv, directions):
    """SampleGrid's fields by numpy: a stable sort of the samples by (row, column) of the pixel of their
    float32-rounded position, counts per pixel of the box, and the least and greatest y of each pixel row's."""
    xy = uv.astype(np.float32).astype(np.float64)
    col, row = np.floor(xy[:, 0]).astype(np.int64), np.floor(xy[:, 1]).astype(np.int64)
    x0, y0 = col.min(), row.min()
    width, height = col.max() - x0 + 1, row.max() - y0 + 1
    pixel = (row - y0) * width + col - x0
    order = np.argsort(pixel, kind="stable")
    start = np.concatenate([[0], np.cumsum(np.bincount(pixel, minlength=width * height))])
    row_band = np.full((2, height), np.nan)
    for r in range(height):
        ys = xy[order[start[r * width]:start[(r + 1) * width]], 1]
        if len(ys):
            row_band[:, r] = ys.min(), ys.max()
    return x0, y0, width, height, order, start, xy[order].T, directions[:, order], row_band


def test_the_sample_grid_is_the_stable_sort_by_pixel_in_order_or_not():
    """Samples that come in pixel order (pixel centres, edge sub-samples) skip the sort (order left empty: the
    identity) and those that do not are sorted; both give numpy's stable sort of the samples by pixel."""
    from darthand.render.aa import sample_offsets

    rng = np.random.default_rng(5)
    centres = trace.pixel_positions(np.flatnonzero(rng.random(40 * 30) < 0.3), 7, -3, 30)
    sub = (centres[:, None, :] + sample_offsets(16)[None]).reshape(-1, 2)
    scattered = rng.uniform(-5.0, 9.0, (200, 2))
    late = np.vstack([centres, centres[:1]])                        # in order but for its last sample
    leftward = centres[np.lexsort((-centres[:, 0], centres[:, 1]))]   # rows in order, each right to left
    for uv, in_order in ((centres, True), (sub, True), (centres[::-1], False), (sub[rng.permutation(len(sub))], False),
                         (scattered, False), (late, False), (leftward, False), (centres[:1], True)):
        directions = rng.standard_normal((3, len(uv))).astype(np.float32)
        grid = raster.SampleGrid(uv, directions)
        x0, y0, width, height, order, start, xy, dirs, row_band = grid_by_numpy(uv, directions)
        assert (grid.x0, grid.y0, grid.width, grid.height) == (x0, y0, width, height)
        assert np.array_equal(grid.order if len(grid.order) else np.arange(len(uv)), order)
        assert (len(grid.order) == 0) == in_order
        assert np.array_equal(grid.start, start) and np.array_equal(grid.xy, xy)
        assert np.array_equal(grid.directions, dirs) and np.array_equal(grid.row_band, row_band, equal_nan=True)


def test_samples_in_any_order_have_the_same_hits(assets, ring, rasterising):
    """A posed hand with a ring, its arm and a face reaching behind the camera (clipped): the pixel centres and
    the sub-samples of every pixel, in pixel order (the sort skipped) and shuffled (sorted), hit the same surface
    and face with the same u, v and depth, to the bit."""
    from darthand.render.aa import sample_offsets

    frame = Renderer(assets, 1).render("fist", camera="three_quarter", width=64, height=64, accessory=ring.id,
                                       arm=ARM_M, labels=False, samples=1)
    cam, hand = frame.camera, frame.subject.hand
    behind = (cam.centre - 0.1 * cam.R[2] + 0.02 * cam.R[1]).astype(np.float32)
    clipped = surface(np.vstack([hand.vertices, behind[None]]), np.vstack([hand.faces, [[0, 1, len(hand.vertices)]]]))
    ctx = context(subject(clipped, *frame.subject.surfaces[1:]), cam)
    rng = np.random.default_rng(2)
    centres = trace.pixel_centres(0, 64, 0, 64)
    for uv in (centres, (centres[:, None, :] + sample_offsets(8)[None]).reshape(-1, 2)):
        shuffle = rng.permutation(len(uv))
        hits, shuffled = trace.intersect_samples(ctx, uv), trace.intersect_samples(ctx, uv[shuffle])
        assert ((hits.geom == 0) & (hits.prim == len(hand.faces))).any() and {0, 1, 2} <= set(hits.geom.tolist())
        for k in ("geom", "prim", "u", "v", "depth", "directions"):
            assert getattr(shuffled, k).tobytes() == getattr(hits.take(shuffle), k).tobytes(), k
