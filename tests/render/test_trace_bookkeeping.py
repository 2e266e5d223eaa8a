"""The compiled bookkeeping around tracing (scene build, camera rays, tiles, scatter, per-surface splits, the
per-triangle anti-aliasing groups) against the numpy chains and the embreex calls they replaced, written out here
as they were: the same bits on the hard cases (no hits, every pixel an edge, a surface leaving the frame, an
accessory present or absent, a scene rebuilt for a new pose, empty batches)."""

from __future__ import annotations

import numpy as np
import pytest
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh
from render_scenes import quad, subject, surface, top_camera

from darthand.render import aa, api, raster, trace
from darthand.render.embree_mesh import _Api, add_triangles, device
from darthand.render.scene import FaceData, Scene, interpolate, interpolate_columns
from darthand.render.trace import Context, RayHits, Samples


# --- the replaced numpy versions -----------------------------------------------------------------------------

def old_face_table(s):
    f = s.faces
    corners = s.vertices[f]
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area2 = np.linalg.norm(n, axis=1)
    rows = [corners.reshape(-1, 9), s.normals[f].reshape(-1, 9), n / np.maximum(area2, 1e-30)[:, None]]
    if s.uvs is not None:
        cuv = s.uvs[s.faces_uv]
        d1, d2 = cuv[:, 1] - cuv[:, 0], cuv[:, 2] - cuv[:, 0]
        uv_area2 = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
        rows += [cuv.reshape(-1, 6), np.sqrt(uv_area2 / np.maximum(area2, 1e-30))[:, None]]
    return np.ascontiguousarray(np.concatenate(rows, axis=1, dtype=np.float32).T)


def old_touched_tiles(camera, surfaces, bounds, tile=trace.TILE):
    r0, r1, c0, c1 = bounds
    rows, cols = -(-(r1 - r0) // tile), -(-(c1 - c0) // tile)
    count = np.zeros((rows + 1) * (cols + 1), np.int64)
    for s in surfaces:
        uv, z = camera.project(s.vertices)
        if (z <= 1e-9).any() or not np.isfinite(uv).all():
            return np.ones((rows, cols), bool)
        a, b, c = uv[s.faces[:, 0]], uv[s.faces[:, 1]], uv[s.faces[:, 2]]
        lo = np.minimum(np.minimum(a, b), c) - [c0 + 1.0, r0 + 1.0]
        hi = np.maximum(np.maximum(a, b), c) - [c0 - 1.0, r0 - 1.0]
        tx0, ty0 = (np.clip(np.floor(lo / tile), 0, [cols, rows]).astype(np.int64)).T
        tx1, ty1 = (np.clip(np.floor(hi / tile) + 1, 0, [cols, rows]).astype(np.int64)).T
        keep = (tx1 > tx0) & (ty1 > ty0)
        tx0, tx1, ty0, ty1 = tx0[keep], tx1[keep], ty0[keep], ty1[keep]
        for ys, xs, sign in ((ty0, tx0, 1), (ty0, tx1, -1), (ty1, tx0, -1), (ty1, tx1, 1)):
            count += sign * np.bincount(ys * (cols + 1) + xs, minlength=len(count))
    return np.cumsum(np.cumsum(count.reshape(rows + 1, cols + 1), 0), 1)[:rows, :cols] > 0


def old_traced(tiles, r0, r1, c0, c1):
    h, w = r1 - r0, c1 - c0
    traced = np.flatnonzero(np.repeat(np.repeat(tiles, trace.TILE, 0), trace.TILE, 1)[:h, :w].reshape(-1))
    return traced, trace.pixel_centres(r0, r1, c0, c1)[traced]


def old_scatter(samples, index, n):
    out = Samples(np.full(n, -1, np.int32), np.full(n, -1, np.int32), np.full(n, np.inf, np.float32),
                  np.zeros((3, n), np.float32), np.zeros((3, n), np.float32))
    out.geom[index], out.prim[index], out.depth[index] = samples.geom, samples.prim, samples.depth
    out.normal[:, index], out.radiance[:, index] = samples.normal, samples.radiance
    return out


def old_intersect(ctx, uv):
    n = len(uv)
    directions = ctx.directions(uv)
    origins = np.broadcast_to(ctx.camera.centre.astype(np.float32), (n, 3))
    hit = ctx.scene.intersect(np.ascontiguousarray(origins), np.ascontiguousarray(directions.T))
    geom = hit["geomID"].astype(np.int32)
    prim = hit["primID"].astype(np.int32)
    geom[prim < 0] = -1
    depth = np.where(geom >= 0, hit["tfar"], np.float32(np.inf)).astype(np.float32)
    return RayHits(geom, prim, hit["u"], hit["v"], depth, directions)


def old_per_triangle(shade, sub, centre_geom, centre_prim, centre_radiance, S):
    key = (sub.geom.astype(np.int64) << 32 | (sub.prim.astype(np.int64) & 0xFFFFFFFF)).reshape(-1, S)
    centre_key = centre_geom.astype(np.int64) << 32 | (centre_prim.astype(np.int64) & 0xFFFFFFFF)
    hit = sub.geom.reshape(-1, S) >= 0
    first = np.argmax(key[:, :, None] == key[:, None, :], axis=2)
    as_centre = hit & (key == centre_key[:, None])
    own = hit & ~as_centre & (first == np.arange(S)[None, :])
    radiance = np.zeros((3,) + key.shape, np.float32)
    rows, cols = np.nonzero(as_centre)
    radiance[:, rows, cols] = centre_radiance[:, rows]
    shade_at = np.flatnonzero(own)
    if len(shade_at):
        radiance.reshape(3, -1)[:, shade_at] = shade(sub.take(shade_at))
    rows, cols = np.nonzero(hit & ~as_centre & ~own)
    radiance[:, rows, cols] = radiance[:, rows, first[rows, cols]]
    return radiance.reshape(3, -1), len(shade_at)


def old_rays_near_sphere(origins, directions, centre, radius):
    w = (centre[None, :] - origins).T
    d = directions.T
    wd = w[0] * d[0] + w[1] * d[1] + w[2] * d[2]
    dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    ww = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
    r2 = np.float32((radius * (1 + 1e-3) + 1e-6) ** 2)
    near = (ww * dd - wd * wd < (r2 + np.float32(1e-6) * ww) * dd) & ((wd > 0) | (ww < r2))
    return np.flatnonzero(near)


# --- helpers -------------------------------------------------------------------------------------------------

def same(a, b):
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b, equal_nan=True)


def random_rays(rng, lo, hi, n):
    o = (lo + (hi - lo) * rng.uniform(-1, 2, (n, 3))).astype(np.float32)
    d = (lo + (hi - lo) * rng.uniform(0, 1, (n, 3))).astype(np.float32) - o
    return o, d


def posed_subjects(assets, ring):
    """A hand with the ring, the same pose without it, and another pose (other vertex arrays)."""
    rng = np.random.default_rng(3)
    pose = rng.normal(0, 0.15, 48)
    return (assets.subject(pose, accessory=ring.id), assets.subject(pose),
            assets.subject(pose + rng.normal(0, 0.2, 48), accessory=ring.id))


def hand_context(subj, size=96, scene=None):
    from darthand.render.camera import load_camera

    cam = load_camera("three_quarter", subj.all_vertices(), width=size, height=size, side=subj.side)
    return Context(scene or Scene(subj), cam, [], np.zeros(3, np.float32))


# --- scene build -----------------------------------------------------------------------------------------------

def test_embree_meshes_by_buffer_copy_hit_as_embreex_meshes(assets, ring):
    assert _Api.load() is not None, "embreex's scene layout was not recognised: meshes go the slow way"
    rng = np.random.default_rng(0)
    for subj in posed_subjects(assets, ring):
        a, b = rtcore_scene.EmbreeScene(device()), rtcore_scene.EmbreeScene(device())
        for s in subj.surfaces:                        # several geometries per scene: geomIDs in order
            TriangleMesh(a, np.ascontiguousarray(s.vertices, np.float32), np.ascontiguousarray(s.faces, np.int32))
            add_triangles(b, s.vertices, s.faces)
        pts = subj.all_vertices()
        o, d = random_rays(rng, pts.min(0), pts.max(0), 20000)
        ha, hb = a.run(o, d, output=1), b.run(o, d, output=1)
        assert (ha["primID"] >= 0).mean() > 0.3 and len(np.unique(ha["geomID"][ha["primID"] >= 0])) == len(
            subj.surfaces)
        for k in ha:
            assert same(ha[k], hb[k]), k
        tfar = np.full(len(o), 0.05, np.float32)
        assert same(a.run(o, d, dists=tfar.copy(), query="OCCLUDED"), b.run(o, d, dists=tfar.copy(),
                                                                               query="OCCLUDED"))


def test_an_empty_mesh_adds_a_geometry_as_embreex_does():
    a, b = rtcore_scene.EmbreeScene(device()), rtcore_scene.EmbreeScene(device())
    q = quad(size=1.0)
    for scene in (a, b):
        (TriangleMesh if scene is a else add_triangles)(scene, np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32))
    TriangleMesh(a, q.vertices, q.faces)
    add_triangles(b, q.vertices, q.faces)
    o = np.array([[0.1, 0.2, 1.0]], np.float32)
    d = np.array([[0, 0, -1]], np.float32)
    ha, hb = a.run(o, d, output=1), b.run(o, d, output=1)
    assert ha["geomID"][0] == hb["geomID"][0] == 1 and same(ha["tfar"], hb["tfar"])


def test_face_tables_match_the_numpy_chain(assets, ring):
    rng = np.random.default_rng(1)
    surfaces = [s for subj in posed_subjects(assets, ring) for s in subj.surfaces]
    v = (rng.normal(size=(300, 3)) * 1e-3).astype(np.float32)
    f = rng.integers(0, 300, (900, 3)).astype(np.int32)
    f[:20, 2] = f[:20, 1]                              # degenerate faces (zero area)
    v[:10] = 0                                         # coincident vertices
    surfaces += [surface(v, f), surface(v, f, uvs=rng.uniform(size=(50, 2)), faces_uv=rng.integers(0, 50, (900, 3)))]
    for s in surfaces:
        table = FaceData(s).table
        assert same(table, old_face_table(s)), s.name
        assert table.shape[0] == (28 if s.uvs is not None else 21)


@pytest.mark.parametrize("rasterised", [False, True])
def test_scenes_rebuilt_for_new_poses_trace_as_fresh_ones(assets, ring, monkeypatch, rasterised):
    """A renderer keeps one scene and rebuilds it when the pose changes; reuse only for the same arrays. Embree's
    camera rays against the numpy chain on a fresh scene; rasterised ones (raster.SceneMesh, kept per scene arrays)
    against a fresh scene's, its mesh built anew."""
    from darthand.render.scene import scene_for

    monkeypatch.setattr(raster, "ENABLED", rasterised)
    with_ring, without, moved = posed_subjects(assets, ring)
    scene = scene_for(with_ring)
    assert scene_for(with_ring, scene).embree is scene.embree
    for subj in (without, moved, with_ring):
        scene = scene_for(subj, scene)
        ctx = hand_context(subj, scene=scene)
        uv = trace.pixel_centres(0, 96, 0, 96)
        new = trace.intersect_samples(ctx, uv)
        fresh = hand_context(subj, scene=Scene(subj))
        monkeypatch.setattr(raster.SceneMesh, "_last", ((), None))      # the reference builds its own mesh
        ref = trace.intersect_samples(fresh, uv) if rasterised else old_intersect(fresh, uv)
        assert (new.geom >= 0).any()
        for k in ("geom", "prim", "u", "v", "depth", "directions"):
            assert same(getattr(new, k), getattr(ref, k)), k
        roles = {subj.surfaces[g].role for g in np.unique(new.geom[new.geom >= 0])}
        assert "hand" in roles and ("accessory" in roles) == (subj.accessory is not None)


# --- camera rays, tiles, traced pixels, scatter --------------------------------------------------------------

def test_tiles_and_traced_pixels_match_the_numpy_chain(assets, ring):
    with_ring, _, _ = posed_subjects(assets, ring)
    ctx = hand_context(with_ring, size=200)
    cam = ctx.camera
    cases = [trace.scene_bounds(cam, with_ring.all_vertices()), (0, 200, 0, 200), (37, 121, 5, 190), (50, 51, 3, 4),
             (100, 100, 20, 40)]
    leaving = subject(surface(with_ring.hand.vertices + np.float32(0.05) * cam.R[0].astype(np.float32),
                              with_ring.hand.faces))          # slides off the image's side
    behind = subject(surface(np.vstack([with_ring.hand.vertices, cam.centre[None].astype(np.float32)
                                        - np.float32(0.1) * cam.R[2].astype(np.float32)]),
                             with_ring.hand.faces))           # a vertex behind the camera: every tile
    assert old_touched_tiles(cam, behind.surfaces, cases[0]).all()
    for subj in (with_ring, leaving, behind):
        for bounds in cases:
            tiles = trace.touched_tiles(cam, subj.surfaces, bounds)
            assert same(tiles, old_touched_tiles(cam, subj.surfaces, bounds))
            r0, r1, c0, c1 = bounds
            traced = trace.tile_pixels(tiles, r1 - r0, c1 - c0)
            ref_traced, ref_uv = old_traced(tiles, *bounds)
            assert same(traced, ref_traced) and same(trace.pixel_positions(traced, r0, c0, c1 - c0), ref_uv)
    grid = (-(-20 // trace.TILE), -(-29 // trace.TILE))
    for tiles in (np.zeros(grid, bool), np.ones(grid, bool)):                 # no tile, every tile
        assert same(trace.tile_pixels(tiles, 20, 29), old_traced(tiles, 0, 20, 0, 29)[0])


def test_scatter_matches_the_numpy_chain():
    rng = np.random.default_rng(2)
    n = 500
    for index in (np.arange(0), np.sort(rng.choice(n, 137, replace=False)), np.array([0, n - 1])):
        m = len(index)
        s = Samples(rng.integers(-1, 2, m).astype(np.int32), rng.integers(-1, 9, m).astype(np.int32),
                    rng.uniform(size=m).astype(np.float32), rng.normal(size=(3, m)).astype(np.float32),
                    rng.normal(size=(3, m)).astype(np.float32))
        new, ref = api.scatter(s, index, n), old_scatter(s, index, n)
        for k in ("geom", "prim", "depth", "normal", "radiance"):
            assert same(getattr(new, k), getattr(ref, k)), k


def test_camera_rays_and_hits_with_no_hits_and_empty_batches(assets, ring, monkeypatch):
    monkeypatch.setattr(raster, "ENABLED", False)          # Embree's camera rays against the numpy chain
    with_ring, _, _ = posed_subjects(assets, ring)
    ctx = hand_context(with_ring)
    for uv in (np.zeros((0, 2)), np.array([[0.5, 0.5], [95.5, 0.5]]), trace.pixel_centres(20, 70, 10, 90)):
        new, ref = trace.intersect_samples(ctx, uv), old_intersect(ctx, uv)
        for k in ("geom", "prim", "u", "v", "depth", "directions"):
            assert same(getattr(new, k), getattr(ref, k)), k


def test_hits_split_by_surface_as_flatnonzero_and_take(assets, ring):
    with_ring, _, _ = posed_subjects(assets, ring)
    ctx = hand_context(with_ring)
    hits = trace.intersect_samples(ctx, trace.pixel_centres(0, 96, 0, 96))
    for part in (hits, hits.take(slice(0, 0)), hits.take(np.flatnonzero(hits.geom < 0))):
        for g in (0, 1, 2, 5):
            idx, on = trace.hits_on(part, g)
            ref_idx = np.flatnonzero(part.geom == g)
            ref = part.take(ref_idx)
            assert same(idx, ref_idx.astype(np.int64))
            for k in ("geom", "prim", "u", "v", "depth", "directions"):
                assert same(getattr(on, k), getattr(ref, k)), k


def test_sphere_culling_matches_the_numpy_chain():
    from darthand.render.scene import _rays_near_sphere

    rng = np.random.default_rng(5)
    centre, radius = np.float32([0.1, -0.2, 0.3]), 0.05
    for n in (0, 1, 5000):
        origins = rng.normal(scale=0.3, size=(n, 3)).astype(np.float32)
        dirs = (centre + rng.normal(scale=0.06, size=(n, 3)) - origins).astype(np.float32)
        blocked = rng.uniform(size=n) < 0.3
        ref = old_rays_near_sphere(origins, dirs, centre, radius)
        assert same(_rays_near_sphere(origins, dirs, centre, radius), ref)
        rest = np.flatnonzero(~blocked)                 # occluded(): rays already blocked are not tested again
        assert same(_rays_near_sphere(origins, dirs, centre, radius, blocked),
                    rest[old_rays_near_sphere(origins[rest], dirs[rest], centre, radius)])


def test_interpolation_matches_interpolate():
    """Rows of per-vertex values (a skin radius, VertexLight's E and V) at all hits, and at some hits into their
    columns of an array that keeps the others."""
    rng = np.random.default_rng(4)
    faces = rng.integers(0, 60, (40, 3)).astype(np.int32)
    for rows in (1, 4):
        values = rng.uniform(1e-3, 2e-2, (rows, 60)).astype(np.float32)
        for m in (0, 1, 300):
            prim = rng.integers(0, 40, m).astype(np.int32)
            bu, bv = rng.uniform(0, 0.5, (2, m)).astype(np.float32)
            want = interpolate(values.T, faces, prim, bu, bv).T
            assert same(interpolate_columns(values, faces, prim, bu, bv), np.ascontiguousarray(want))
            some = np.flatnonzero(rng.random(m) < 0.3)
            out = np.full((rows, m), -1.0, np.float32)
            interpolate_columns(values, faces, prim, bu, bv, rays=some, out=out)
            keep = np.full((rows, m), -1.0, np.float32)
            keep[:, some] = want[:, some]
            assert same(out, keep)


# --- anti-aliasing --------------------------------------------------------------------------------------------

def fake_shade(sub):
    """A colour that tells apart every (geom, prim, barycentric) it is asked for."""
    return np.stack([sub.prim * np.float32(0.001) + sub.u, sub.geom + sub.v, sub.depth]).astype(np.float32)


@pytest.mark.parametrize("S", [1, 4, 16])
def test_per_triangle_groups_match_the_numpy_chain(monkeypatch, S):
    rng = np.random.default_rng(S)
    monkeypatch.setattr(aa, "shade_parallel", lambda ctx, sub, footprint, stats: (None, fake_shade(sub)))
    for P, kind in ((0, "empty"), (50, "background"), (50, "mixed"), (50, "centre")):
        n = P * S
        geom = rng.integers(-1, 2, n).astype(np.int32) if kind == "mixed" else np.full(
            n, -1 if kind == "background" else 0, np.int32)
        prim = rng.integers(0, 3, n).astype(np.int32)
        prim[geom < 0] = -1
        sub = RayHits(geom, prim, rng.uniform(size=n).astype(np.float32), rng.uniform(size=n).astype(np.float32),
                      rng.uniform(1, 2, n).astype(np.float32), rng.normal(size=(3, n)).astype(np.float32))
        centre_geom = rng.integers(-1, 2, P).astype(np.int32) if kind != "centre" else np.zeros(P, np.int32)
        centre_prim = rng.integers(0, 3, P).astype(np.int32) if kind != "centre" else prim.reshape(P, S)[:, 0].copy()
        centre_radiance = rng.normal(size=(3, P)).astype(np.float32)
        new = aa._shade_per_triangle(None, sub, centre_geom, centre_prim, centre_radiance, S, None)
        ref = old_per_triangle(fake_shade, sub, centre_geom, centre_prim, centre_radiance, S)
        assert same(new[0], ref[0]) and new[1] == ref[1], kind


def test_a_frame_whose_every_pixel_is_an_edge():
    """A pixel-sized checkerboard of two surfaces seen from above: every pixel of the 16 x 16 image is an edge and
    is supersampled; it is fully covered, and 'triangle' shading (one colour per pixel and triangle) equals
    'sample' shading on this flat, evenly lit board."""
    from render_scenes import one_light

    height, size, fov = 4.0, 16, 28.0
    cell = 2 * height * np.tan(np.deg2rad(fov / 2)) / size
    boards = {0: [], 1: []}
    for i in range(size):
        for j in range(size):
            boards[(i + j) % 2].append(quad(centre=((j - 7.5) * cell, (i - 7.5) * cell, 0.0), size=cell))
    surfaces = [surface(np.concatenate([c.vertices for c in cells]),
                        np.concatenate([c.faces + 4 * k for k, c in enumerate(cells)]), name=f"board{g}")
                for g, cells in boards.items()]
    subj = subject(*surfaces)
    cam = top_camera(height=height, size=size, fov_deg=fov)
    frames = [api.render_subject(subj, Scene(subj), cam, one_light((0.3, 0.2, -1.0)), samples=4, aa_shading=mode,
                                 shading={"ao_rays": 0}, labels=False) for mode in ("triangle", "sample")]
    assert frames[0].stats["edge_pixels"] == size * size
    assert (frames[0].alpha == 1).all() and (frames[0].geom >= 0).all()
    assert len(np.unique(frames[0].geom)) == 2
    np.testing.assert_array_equal(frames[0].colour, frames[1].colour)
