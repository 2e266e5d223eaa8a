"""The ray-tracing scene's rigid-accessory path against the plain one (the same posed mesh baked into the scene),
and the PNG writer's lossless round trip through an independent reader (OpenImageIO)."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import trimesh

from darthand.render.image import write_exr, write_png
from darthand.render.scene import Scene
from darthand.render.subject import Material, Subject, Surface


def _surface(name, vertices, faces, local=None, transform=None) -> Surface:
    v = np.asarray(vertices, np.float32)
    return Surface(name, v, np.asarray(faces, np.int32), np.zeros_like(v), Material(), local=local,
                   transform=transform, role="hand" if name == "hand" else "accessory")


def _subject(surfaces) -> Subject:
    return Subject(tuple(surfaces), np.zeros((16, 3)), np.zeros((21, 3)), "right", np.zeros(48))


def _rigid(seed):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    G = np.eye(4)
    G[:3, :3] = q * np.sign(np.linalg.det(q))
    G[:3, 3] = [0.0, 0.0, 0.06]          # above the box, between it and the rays' origin
    return G


def test_rigid_accessory_hits_match_the_baked_mesh():
    box = trimesh.creation.box((0.04, 0.02, 0.08))
    ring = trimesh.creation.annulus(0.009, 0.012, 0.006)
    G = _rigid(3)
    local = np.ascontiguousarray(ring.vertices, np.float32)
    world = local.astype(np.float64) @ G[:3, :3].T + G[:3, 3]
    hand = _surface("hand", box.vertices, box.faces)
    rigid = Scene(_subject([hand, _surface("ring", world, ring.faces, local, G)]))
    baked = Scene(_subject([hand, _surface("ring", world, ring.faces)]))
    assert len(rigid.rigid) == 1 and not baked.rigid
    rng = np.random.default_rng(0)
    n = 4000
    origins = np.tile(np.float32([0.0, 0.0, 0.3]), (n, 1)) + rng.normal(scale=0.003, size=(n, 3)).astype(np.float32)
    targets = rng.uniform(-0.03, 0.03, size=(n, 3))
    dirs = np.ascontiguousarray((targets - origins) / np.linalg.norm(targets - origins, axis=1)[:, None], np.float32)
    a, b = rigid.intersect(origins, dirs), baked.intersect(origins, dirs)
    assert (a["geomID"] == 1).sum() > 100 and (a["geomID"] == 0).sum() > 100
    # Rays grazing a triangle edge may pick a neighbour after the float32 transform: allow a few.
    same = (a["geomID"] == b["geomID"]) & (a["primID"] == b["primID"])
    assert same.mean() > 0.995
    np.testing.assert_allclose(a["tfar"][same & (a["geomID"] >= 0)], b["tfar"][same & (b["geomID"] >= 0)],
                               atol=1e-5)
    hit = b["geomID"] >= 0
    for scene in (rigid, baked):
        # Within the whole ray every hit ray is blocked; short of the nearest hit none is.
        assert (scene.occluded(origins, dirs, 1.0) == hit).mean() > 0.995
        short = np.where(hit, b["tfar"] * 0.999, 1.0).astype(np.float32)
        assert (~scene.occluded(origins, dirs, short)).mean() > 0.995

def test_png_round_trip_is_lossless(tmp_path):
    rng = np.random.default_rng(1)
    for shape in ((17, 23), (17, 23, 3), (5, 9, 4)):
        img = rng.integers(0, 256, size=shape, dtype=np.uint8)
        path = tmp_path / f"{len(shape)}_{shape[-1]}.png"
        write_png(path, img, srgb=len(shape) == 3)
        cfg = oiio.ImageSpec()
        cfg.attribute("oiio:UnassociatedAlpha", 1)
        back = oiio.ImageBuf(str(path), 0, 0, cfg).get_pixels(oiio.UINT8)
        np.testing.assert_array_equal(back, img.reshape(img.shape[0], img.shape[1], -1))
        first = path.read_bytes()
        write_png(path, img, srgb=len(shape) == 3)
        assert path.read_bytes() == first


def test_exr_bytes_do_not_depend_on_the_clock(tmp_path, monkeypatch):
    """OpenImageIO stamps the write time into EXR headers (capDate) unless told not to; the same depth map written
    at two different times must give the same bytes, and read back exactly."""
    depth = np.linspace(0.0, 2.0, 48, dtype=np.float32).reshape(6, 8)
    write_exr(tmp_path / "a.exr", depth)
    data = (tmp_path / "a.exr").read_bytes()
    assert b"capDate" not in data
    back = oiio.ImageBuf(str(tmp_path / "a.exr")).get_pixels(oiio.FLOAT)[..., 0]
    np.testing.assert_array_equal(back, depth)


def test_sphere_culling_keeps_every_ray_that_passes_near():
    """scene._rays_near_sphere against float64 point-to-ray distances: no ray within the radius is dropped, and
    rays clearly outside it (or pointing away) are."""
    from darthand.render.scene import _rays_near_sphere

    rng = np.random.default_rng(1)
    n = 20000
    origins = rng.normal(scale=2.0, size=(n, 3)).astype(np.float32)
    centre, radius = np.float32([0.1, -0.2, 0.3]), 0.05
    aim = centre + rng.normal(scale=0.06, size=(n, 3))
    dirs = (aim - origins) * rng.choice([-1.0, 1.0], size=(n, 1)) * rng.uniform(0.1, 3, size=(n, 1))
    dirs = dirs.astype(np.float32)
    o, d, c = origins.astype(np.float64), dirs.astype(np.float64), centre.astype(np.float64)
    s = np.maximum(np.einsum("ij,ij->i", c - o, d) / np.einsum("ij,ij->i", d, d), 0)
    dist = np.linalg.norm(o + s[:, None] * d - c, axis=1)
    kept = np.zeros(n, bool)
    kept[_rays_near_sphere(origins, dirs, centre, radius)] = True
    assert (dist < radius).sum() > 1000 and (dist > radius * 1.01).sum() > 1000
    assert kept[dist < radius].all()
    assert not kept[dist > radius * 1.01].any()
