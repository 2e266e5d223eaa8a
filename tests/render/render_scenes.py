"""Small scenes with known answers for the renderer's tests (planes, triangles, built here, rendered through the same
path as the hand: Subject -> Scene -> render_subject), and the fixtures' building blocks (images, a ring)."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio

from darthand.accessories.loader import Accessory
from darthand.render.api import render_subject
from darthand.render.camera import look_at
from darthand.render.lights import Light, Lighting
from darthand.render.scene import Scene
from darthand.model.topology import vertex_normals
from darthand.render.subject import Material, Subject, Surface
from darthand.render.texture import constant_texture


def flat_material(albedo=(0.5, 0.5, 0.5), **kw) -> Material:
    """Lambert only: no specular, no wrap."""
    return Material("pbr", constant_texture(albedo), None, 0.5, None, 0.0, (0.0, 0.0, 0.0), 0.0, "flat",
                    specular=0.0, **kw)


def surface(vertices, faces, material=None, uvs=None, faces_uv=None, role="hand", name="s") -> Surface:
    v = np.asarray(vertices, np.float32)
    f = np.asarray(faces, np.int32)
    return Surface(name, v, f, vertex_normals(v, f), material or flat_material(),
                   None if uvs is None else np.asarray(uvs, np.float32),
                   None if faces_uv is None else np.asarray(faces_uv, np.int32), v.astype(np.float64), role)


def quad(centre=(0, 0, 0), size=1.0, normal_axis=2, **kw) -> Surface:
    """A square of side `size` centred at `centre`, in the plane normal to `normal_axis`, facing +axis, with UVs
    [0, 1]^2 (u along the first other axis, v along the second)."""
    a, b = [k for k in range(3) if k != normal_axis]
    corners = np.zeros((4, 3))
    for i, (s, t) in enumerate([(-1, -1), (1, -1), (1, 1), (-1, 1)]):
        corners[i, a], corners[i, b] = s * size / 2, t * size / 2
    corners += centre
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    if np.cross(corners[1] - corners[0], corners[2] - corners[0])[normal_axis] < 0:
        faces = faces[:, ::-1]
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    return surface(corners, faces, uvs=uvs, faces_uv=faces, **kw)


def subject(*surfaces, keypoints=None) -> Subject:
    kp = np.zeros((21, 3)) if keypoints is None else np.asarray(keypoints, np.float64)
    return Subject(tuple(surfaces), np.zeros((16, 3)), kp, "right", np.zeros(48), "openpose", {"texture": "t"})


def one_light(direction, intensity=1.0, shadows=True, ambient=0.0, frame="world") -> Lighting:
    return Lighting((1.0, 1.0, 1.0), ambient, (Light("directional", (1.0, 1.0, 1.0), intensity,
                                                       direction=tuple(direction), shadows=shadows, frame=frame),))


def render(subj: Subject, camera, lighting: Lighting, **kw):
    return render_subject(subj, Scene(subj), camera, lighting, **kw)


def top_camera(height=2.0, size=64, fov_deg=40.0):
    """Looking down -z from (0, 0, height) at the origin, +y up in the image."""
    return look_at((0, 0, height), (0, 0, 0), (0, 1, 0), width=size, height=size, fov_deg=fov_deg)


RING_JOINT = 2          # index2: the ring sits on the index finger's middle phalanx


def write_image(path, img: np.ndarray):
    img = np.ascontiguousarray(img)
    if img.ndim == 2:
        img = img[..., None]
    buf = oiio.ImageBuf(oiio.ImageSpec(img.shape[1], img.shape[0], img.shape[2], oiio.UINT8))
    buf.set_pixels(oiio.ROI(), img)
    path.parent.mkdir(parents=True, exist_ok=True)
    assert buf.write(str(path))
    return path


def ring_around(model, joint: int, child: int, radius_scale: float = 1.25, tube: float = 0.0015) -> Accessory:
    """A torus around the bone joint -> child at its middle, its radius the finger's radius there (mean distance of
    the nearby vertices from the bone axis) times `radius_scale`; rigidly bound to `joint`."""
    J = model.J_regressor @ model.v_template
    a, b = J[joint], J[child]
    axis = (b - a) / np.linalg.norm(b - a)
    centre = 0.5 * (a + b)
    rel = model.v_template - centre
    along = rel @ axis
    radial = np.linalg.norm(rel - np.outer(along, axis), axis=1)
    near = (np.abs(along) < 0.004) & (radial < 0.02)
    R = radius_scale * radial[near].mean()
    u = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    v = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    e1 = np.cross(axis, [0, 0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    ring_dir = np.cos(uu)[..., None] * e1 + np.sin(uu)[..., None] * e2
    pts = centre + (R + tube * np.cos(vv))[..., None] * ring_dir + (tube * np.sin(vv))[..., None] * axis
    n_u, n_v = len(u), len(v)
    idx = np.arange(n_u * n_v).reshape(n_u, n_v)
    a_, b_ = idx, np.roll(idx, -1, 0)
    c_, d_ = np.roll(idx, -1, 1), np.roll(np.roll(idx, -1, 0), -1, 1)
    faces = np.concatenate([np.stack([a_, b_, d_], -1).reshape(-1, 3), np.stack([a_, d_, c_], -1).reshape(-1, 3)])
    return Accessory("ring_test", pts.reshape(-1, 3), faces, parent_joint=joint,
                     material={"base_color": [1.0, 0.77, 0.34], "metallic": 1.0, "roughness": 0.25}, kind="ring")


def assert_only_shading_differs(on, off) -> None:
    """Two renders of one scene (api.Frame) whose shading options differ: the same mask, geometry, depth, truth
    maps and labels (but the labels' shading record)."""
    assert np.array_equal(on.alpha, off.alpha) and np.array_equal(on.geom, off.geom)
    assert np.array_equal(on.depth, off.depth)
    assert on.maps.keys() == off.maps.keys()
    for kind in on.maps:
        assert np.array_equal(on.maps[kind], off.maps[kind]), kind

    def strip(labels):
        return {**labels, "render": {**labels["render"], "shading": None}}
    assert strip(on.labels) == strip(off.labels)
