"""Shadow rays at vertex rate (render/shadows.py, ShadingOptions.shadows 'vertex') against closed forms: a box's
shadow on a tessellated floor (a floor sample is dark exactly when its ray toward the light meets the box; the
vertex mode agrees wherever the shadow's edge does not cross a triangle), a light behind a surface (unlit, no ray),
a scene without occluders (the same bytes as a ray per sample), the corners' bookkeeping (one ray per vertex and
side, a ray per sample only where the corners disagree), what it cannot see (an occluder between a face's
corners), and a hand's labels, mask and maps unchanged by the option."""

from __future__ import annotations

import numpy as np
import pytest
from render_scenes import assert_only_shading_differs, one_light, quad, render, subject, surface, top_camera

from darthand.errors import InputError
from darthand.render.api import Renderer
from darthand.render.camera import look_at
from darthand.render.lights import Light, Lighting
from darthand.render import shade
from darthand.render.shade import ShadingOptions
from darthand.render.shadows import hit_corners, sample_rays, vertex_rate_occlusion
from darthand.render.skin import sphere_blend_table

LIGHT = np.array([np.sin(np.pi / 5), 0.1, -np.cos(np.pi / 5)])       # travelling down and toward +x
BOX = (np.array([0.0, 0.0, 0.5]), 0.2)                               # centre, half side (m)


def shading(mode: str) -> dict:
    """Direct light only (no ambient rays), Lambert: a shadowed floor sample is exactly black."""
    return {"ao_rays": 0, "skin": "lambert", "shadows": mode}


def grid(n: int, size: float, name: str = "floor"):
    """A floor of n x n cells of side size / n at z = 0, two triangles a cell, facing +z."""
    t = np.linspace(-size / 2, size / 2, n + 1)
    x, y = np.meshgrid(t, t, indexing="xy")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return surface(vertices, faces, name=name)


def box(centre, half: float):
    """A closed cube, outward-facing triangles."""
    corners = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], float) * half + centre
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    faces = [f for a, b, c, d in quads for f in ((a, b, c), (a, c, d))]
    return surface(corners, faces, name="box", role="accessory")


def meets_box(points: np.ndarray, toward: np.ndarray, centre: np.ndarray, half: float) -> np.ndarray:
    """(N,) bool: the rays from points (N, 3) along `toward` (3,) meet the axis-aligned box (slab test)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (centre - half - points) / toward
        t1 = (centre + half - points) / toward
    near = np.nanmax(np.minimum(t0, t1), axis=1)
    far = np.nanmin(np.maximum(t0, t1), axis=1)
    return (far >= np.maximum(near, 0)) & (far > 0)


def floor_points(cam, rows: np.ndarray, cols: np.ndarray, du: float = 0.0, dv: float = 0.0) -> np.ndarray:
    """(N, 3) where the camera rays through pixel centres (+ du, dv pixels) meet the plane z = 0."""
    uv = np.stack([cols + 0.5 + du, rows + 0.5 + dv], axis=1)
    d = cam.directions(uv)
    t = -cam.centre[2] / d[:, 2]
    return cam.centre + t[:, None] * d


def box_scene():
    floor = grid(12, 2.0)
    light = Lighting((1, 1, 1), 0.0, (Light("directional", (1, 1, 1), 1.0, direction=tuple(LIGHT), shadows=True,
                                            frame="world"),))
    cam = look_at((0.3, 0, 6), (0.3, 0, 0), (0, 1, 0), width=96, height=96, focal_px=96 * 6 / 2.2)
    return subject(floor, box(*BOX)), cam, light


def test_a_box_shadow_is_each_samples_ray_and_the_vertex_mode_agrees_off_its_edge():
    subj, cam, light = box_scene()
    frames = {m: render(subj, cam, light, samples=1, labels=False, shading=shading(m)) for m in ("pixel", "vertex")}
    rows, cols = np.nonzero(frames["pixel"].geom == 0)                  # the floor's pixels
    toward = -LIGHT / np.linalg.norm(LIGHT)
    p = floor_points(cam, rows, cols)
    want = meets_box(p, toward, *BOX)
    near_edge = np.zeros(len(p), bool)                                  # the box's shadow edge within a pixel
    for du, dv in ((-0.5, 0), (0.5, 0), (0, -0.5), (0, 0.5)):
        near_edge |= meets_box(floor_points(cam, rows, cols, du, dv), toward, *BOX) != want
    dark = {m: f.colour[rows, cols, 0] < 1e-6 for m, f in frames.items()}
    assert want.sum() > 200 and (~want).sum() > 2000
    assert np.array_equal(dark["pixel"][~near_edge], want[~near_edge])
    # a floor triangle the shadow's edge does not cross: its corners and every point inside agree
    n, size = 12, 2.0
    cell = np.clip(np.floor((p[:, :2] + size / 2) / (size / n)).astype(int), 0, n - 1)
    fx, fy = (p[:, 0] + size / 2) / (size / n) - cell[:, 0], (p[:, 1] + size / 2) / (size / n) - cell[:, 1]
    upper = fx >= fy                                                    # triangle (a, b, c) of the cell, else (a, c, d)
    crossed = np.zeros(len(p), bool)
    s = np.linspace(0, 1, 9)
    for i in np.unique(cell[:, 1] * n + cell[:, 0]):
        cy, cx = divmod(i, n)
        u, v = np.meshgrid(s, s)
        for tri_upper in (True, False):
            inside = (u >= v) if tri_upper else (u <= v)
            pts = np.stack([(cx + u[inside]) * size / n - size / 2, (cy + v[inside]) * size / n - size / 2,
                            np.zeros(inside.sum())], axis=1)
            answers = meets_box(pts, toward, *BOX)
            if answers.min() != answers.max():
                crossed[(cell[:, 0] == cx) & (cell[:, 1] == cy) & (upper == tri_upper)] = True
    assert crossed.sum() > 20 and (~crossed & ~near_edge).sum() > 2000
    keep = ~crossed & ~near_edge
    assert np.array_equal(dark["vertex"][keep], want[keep])
    assert frames["vertex"].stats["shadow_rays"] < frames["pixel"].stats["shadow_rays"] / 3


def test_a_light_behind_the_surface_leaves_it_unlit_without_a_ray():
    light = one_light((0, 0, 1), intensity=1.0, shadows=True)           # travelling up: the floor's back is lit
    frame = render(subject(grid(6, 4.0)), top_camera(size=32), light, samples=1, labels=False,
                   shading=shading("vertex"))
    assert np.array_equal(frame.colour, np.zeros_like(frame.colour))
    assert frame.stats.get("shadow_rays", 0) == 0


def test_without_occluders_the_vertex_mode_is_the_pixel_mode_to_the_byte():
    lighting = Lighting((1, 1, 1), 0.1, (
        Light("directional", (1, 0.9, 0.8), 1.2, direction=(0.3, -0.2, -1.0), shadows=True, frame="world"),
        Light("point", (0.8, 0.9, 1), 0.6, position=(0.4, 0.3, 1.0), shadows=True, frame="world")))
    floor = grid(10, 3.0)
    frames = [render(subject(floor), top_camera(size=48), lighting, shading={"shadows": mode}, labels=False)
              for mode in ("pixel", "vertex")]
    assert np.array_equal(frames[0].rgba, frames[1].rgba)
    assert 0 < frames[1].stats["shadow_rays"] < frames[0].stats["shadow_rays"] / 3


def test_an_occluder_between_a_faces_corners_is_missed_and_only_there():
    """The vertex mode's one approximation: a small box over the middle of a large two-triangle floor casts its
    shadow on the per-sample frame, not on the vertex one (no corner's ray meets it)."""
    light = one_light((0, 0, -1), intensity=1.0, shadows=True)
    subj = subject(quad(size=2.0, name="floor"), box(np.array([0.3, -0.2, 0.3]), 0.05))
    cam = top_camera(height=4.0, size=48)
    frames = {m: render(subj, cam, light, samples=1, labels=False, shading=shading(m)) for m in ("pixel", "vertex")}
    floor = frames["pixel"].geom == 0
    dark = {m: (f.colour[..., 0] < 1e-6) & floor for m, f in frames.items()}
    assert dark["pixel"].sum() > 0 and dark["vertex"].sum() == 0
    assert np.array_equal(frames["pixel"].rgba[~floor], frames["vertex"].rgba[~floor])


def test_corners_trace_one_ray_per_vertex_and_side_and_split_faces_trace_their_own():
    """A strip of four faces over x in [0, 2]; an occluder blocks rays leaving x > 1.5 (vertices 4, 5 only). Faces
    (0, 1, 2), (0, 2, 3) agree (lit); (1, 4, 5), (1, 5, 2) disagree: their samples are decided by their own rays.
    A hit seeing a face's back has its corners' rays on that side."""
    positions = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0]], np.float32)
    normals = np.tile(np.array([0, 0, 1], np.float32), (6, 1))
    faces = np.array([[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]])
    table = np.zeros((21, 4), np.float32)
    table[20] = 1                                                      # geometric normals +z
    prim = np.array([0, 0, 1, 1, 2, 2, 3, 1])
    view = np.tile(np.array([[0], [0], [1]], np.float32), (1, len(prim)))
    view[2, -1] = -1                                                   # the last hit sees face 1 from below
    corners = hit_corners(faces, table, positions, normals, prim, view)
    assert corners.slots[-1].tolist() == [1, 5, 7] and corners.slots[0].tolist() == [0, 2, 4]
    x = np.array([0.6, 0.9, 0.2, 0.5, 1.2, 1.8, 1.4, 0.3], np.float32)  # the samples' positions along x
    position = np.stack([x, np.full_like(x, 0.5), np.zeros_like(x)])
    up = np.tile(np.array([[0], [0], [1]], np.float32), (1, len(x)))
    calls = []

    def occluded(o, d, t):
        calls.append(np.array(o))
        return o[:, 0] > 1.5

    light = np.array([0, 0, 0, 1, 1, 1, 1, 1], np.float32)             # directional, toward +z, with shadows
    blocked, traced = vertex_rate_occlusion(corners, np.arange(len(x)), position, up, light, np.float32(0.01),
                                            occluded)
    assert blocked.tolist() == [False, False, False, False, False, True, False, False]
    vertex_rays, own = calls
    assert len(vertex_rays) == 6 + 3                                   # vertices 0..5 above, 0, 2, 3 below
    below = vertex_rays[:, 2] < 0
    assert np.allclose(vertex_rays[below, 2], -0.01) and np.allclose(vertex_rays[~below, 2], 0.01)
    assert np.allclose(own, position[:, [4, 5, 6]].T + [0, 0, 0.01]) and traced == 9 + 3


@pytest.mark.parametrize("point", [False, True])
def test_the_rays_made_where_needed_are_the_per_sample_rays_to_the_bit(point):
    """sample_rays against the rays shade's kernel writes for every reached hit (random hits, a wrap diffuse)."""
    rng = np.random.default_rng(7)
    m = 500
    unit = lambda a: (a / np.linalg.norm(a, axis=0)).astype(np.float32)
    normal, view = unit(rng.normal(size=(3, m))), unit(rng.normal(size=(3, m)))
    position = rng.uniform(-0.1, 0.1, (3, m)).astype(np.float32)
    light = np.array([1.0 if point else 0.0, 0.3, -0.2, 0.9, 1, 1, 1, 1], np.float32)
    if not point:
        light[1:4] /= np.linalg.norm(light[1:4])
    lift = np.float32(0.0005)
    wrap = np.array([0.3, 0.1, 0.0], np.float32)
    nv, e2 = np.empty(m, np.float32), np.empty(m, np.float32)
    diffuse, reached = np.empty((1, 3, m), np.float32), np.empty((1, m), np.bool_)
    origins, directions, tfar = np.empty((m, 3), np.float32), np.empty((m, 3), np.float32), np.empty(m, np.float32)
    ray_hit, offsets = np.empty(m, np.int64), np.zeros(2, np.int64)
    shade._lights_kernel(normal, view, position, light[None], 1, False, wrap, np.zeros(0, np.float32),
                         np.zeros(3, np.float32), np.zeros(0, np.bool_), sphere_blend_table(), lift, nv, e2, diffuse,
                         reached, origins, directions, tfar, ray_hit, offsets)
    k = offsets[1]
    assert 100 < k < m
    made = sample_rays(position, normal, ray_hit[:k], light, lift)
    for got, want in zip(made, (origins[:k], directions[:k], tfar[:k])):
        assert np.array_equal(got.view(np.uint32), want.view(np.uint32))


def test_the_option_is_off_by_default_checked_and_recorded_only_when_on():
    assert ShadingOptions().shadows == "pixel" and "shadows" not in ShadingOptions().to_json()
    assert ShadingOptions(shadows="vertex").to_json()["shadows"] == "vertex"
    with pytest.raises(InputError, match="shadows: 'corner' is not one of pixel, vertex"):
        ShadingOptions(shadows="corner")


def test_a_hands_labels_mask_and_maps_are_unchanged_by_the_option(assets):
    """The vertex mode changes at most a few of the hand's pixels, never its mask, depth, normals, parts or labels
    (beyond the shading record), and traces a fraction of the rays."""
    r = Renderer(assets, threads=1)
    common = dict(camera="three_quarter", width=160, height=160, maps=("depth", "normals", "parts"))
    off = r.render("fist", **common)
    on = r.render("fist", shading={"shadows": "vertex"}, **common)
    assert_only_shading_differs(on, off)
    assert on.labels["render"]["shading"]["shadows"] == "vertex" and "shadows" not in off.labels["render"]["shading"]
    differ = np.abs(on.rgba.astype(int) - off.rgba.astype(int)).max(axis=-1) > 0
    assert differ.sum() <= 0.01 * (off.alpha > 0).sum()
    assert 0 < on.stats["shadow_rays"] < off.stats["shadow_rays"] / 3
    two = Renderer(assets, threads=2).render("fist", shading={"shadows": "vertex"}, **common)
    assert np.array_equal(two.rgba, on.rgba)                           # chunks trace their corners alike
