"""The environment's specular looked up at the corners of the faces hit (render/vertex_specular.py,
ShadingOptions.environment_lookups 'vertex') against the per-sample lookup: exact under a uniform map (the blend of
a constant), converging to it as the mesh is refined under a smooth map, per sample on faces near the silhouette,
only on skin (a metal's narrow lobe stays per sample), and a hand's labels and mask unchanged."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest
import trimesh
from render_scenes import render, subject, surface, top_camera

from darthand.render.api import Renderer
from darthand.render.environment import texel_directions
from darthand.render.lights import load_lighting
from darthand.render.subject import Material, skin_material
from darthand.render.texture import constant_texture
from darthand.render.vertex_specular import GRAZING


def write_exr(path, pixels: np.ndarray):
    pixels = np.ascontiguousarray(pixels, np.float32)
    buf = oiio.ImageBuf(oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.FLOAT))
    buf.set_pixels(oiio.ROI(), pixels)
    assert buf.write(str(path))
    return path


def ball(subdivisions: int, material=None):
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    return surface(mesh.vertices, mesh.faces, material=material or skin_material(), name="ball")


def both(scene, lighting, size=64):
    """(pixel, vertex) frames of a scene under lighting: direct light and the environment only (no ambient rays),
    Lambert skin (its specular is what differs)."""
    cam = top_camera(height=4.0, size=size)
    return [render(scene, cam, lighting, samples=1, labels=False,
                   shading={"ao_rays": 0, "skin": "lambert", "environment_lookups": mode})
            for mode in ("pixel", "vertex")]


def smooth_map(tmp_path):
    """A map varying smoothly with direction: sky brighter and bluer toward the zenith, warmer toward +x."""
    d = texel_directions(64)
    pixels = np.stack([1.0 + 0.6 * d[..., 0], 1.0 + 0.2 * d[..., 2], 1.2 + 0.8 * d[..., 2]], axis=-1)
    return load_lighting({"environment": {"map": str(write_exr(tmp_path / "smooth.exr", pixels)), "frame": "world"}})


def test_under_a_uniform_map_the_corners_blend_to_the_same_colour(tmp_path):
    lighting = load_lighting({"environment": {"map": str(write_exr(tmp_path / "grey.exr",
                                                                   np.full((32, 64, 3), 1.5, np.float32)))}})
    pixel, vertex = both(subject(ball(2)), lighting)
    inside = pixel.alpha == 1
    assert inside.sum() > 500
    assert np.abs(vertex.colour - pixel.colour).max() < 1e-5


def test_under_a_smooth_map_the_error_shrinks_as_the_faces_do(tmp_path):
    """The corners' blend approximates the lookup at the sample's own reflection direction to second order in the
    face's size: on a finer sphere the difference falls (about 4 x per halving of the edges)."""
    lighting = smooth_map(tmp_path)
    errors = []
    for level in (2, 3, 4):
        pixel, vertex = both(subject(ball(level)), lighting, size=96)
        inside = pixel.alpha == 1
        errors.append(np.abs(vertex.colour - pixel.colour)[inside].mean())
    assert errors[0] > 0 and errors[1] < errors[0] / 2 and errors[2] < errors[1] / 2, errors


def test_faces_near_the_silhouette_are_looked_up_per_sample(tmp_path):
    """A sample whose face has a corner seen at n.v < GRAZING gets its own lookup: the pixels of those faces of a
    sphere (found by trimesh's ray query) render as per sample, the others are blended."""
    lighting = smooth_map(tmp_path)
    sphere = ball(2)
    pixel, vertex = both(subject(sphere), lighting, size=96)
    cam = top_camera(height=4.0, size=96)
    rows, cols = np.nonzero(pixel.alpha == 1)
    d = cam.directions(np.stack([cols + 0.5, rows + 0.5], axis=1))
    mesh = trimesh.Trimesh(sphere.vertices, sphere.faces, process=False)
    face = mesh.ray.intersects_first(np.tile(cam.centre, (len(d), 1)), d)
    assert (face >= 0).all()
    toward = cam.centre - sphere.vertices
    toward /= np.linalg.norm(toward, axis=1, keepdims=True)
    unit = sphere.normals / np.linalg.norm(sphere.normals, axis=1, keepdims=True)
    facing = (unit * toward).sum(axis=1)[sphere.faces].min(axis=1)             # per face, its lowest corner
    rim = facing[face] < GRAZING
    assert rim.sum() > 100 and (~rim).sum() > 1000
    got, want = vertex.colour[rows, cols], pixel.colour[rows, cols]
    assert np.abs(got[rim] - want[rim]).max() < 1e-6
    assert np.abs(got[~rim] - want[~rim]).max() > 1e-4


def test_a_metal_is_looked_up_per_sample(tmp_path):
    metal = Material("pbr", constant_texture((0.9, 0.9, 0.9)), None, 0.2, None, 1.0, (0.0, 0.0, 0.0), 0.04, "metal")
    pixel, vertex = both(subject(ball(2, metal)), smooth_map(tmp_path))
    assert np.array_equal(pixel.rgba, vertex.rgba)


def test_the_option_is_off_by_default_and_recorded_only_when_on():
    from darthand.errors import InputError
    from darthand.render.shade import ShadingOptions

    assert ShadingOptions().environment_lookups == "pixel" and "environment_lookups" not in ShadingOptions().to_json()
    assert ShadingOptions(environment_lookups="vertex").to_json()["environment_lookups"] == "vertex"
    with pytest.raises(InputError, match="environment_lookups: 'cube' is not one of pixel, vertex"):
        ShadingOptions(environment_lookups="cube")


def test_a_hands_labels_and_mask_are_unchanged_by_the_option(assets):
    lights = {"environment": {"map": "sunrise", "rotation": 40, "strength": 1.5}}
    common = dict(camera="three_quarter", width=128, height=128, lights=lights, maps=("depth", "normals", "parts"))
    r = Renderer(assets, threads=1)
    off = r.render("fist", **common)
    on = r.render("fist", shading={"environment_lookups": "vertex"}, **common)
    assert np.array_equal(on.alpha, off.alpha) and np.array_equal(on.geom, off.geom)
    for kind in ("depth", "normals", "parts"):
        assert np.array_equal(on.maps[kind], off.maps[kind])
    strip = lambda labels: {**labels, "render": {**labels["render"], "shading": None}}
    assert strip(on.labels) == strip(off.labels)
    assert on.labels["render"]["shading"]["environment_lookups"] == "vertex"
    hand = off.alpha > 0
    assert not np.array_equal(on.rgba, off.rgba)
    assert np.abs(on.rgba.astype(int) - off.rgba.astype(int))[hand].mean() < 1.0
