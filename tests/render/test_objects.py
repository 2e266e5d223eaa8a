"""A hand holding an object (render/objects.py, render/bodies.py, render/labels.object_fields): the object's pixels
against the object and the hand rendered alone, a fingertip hidden behind the object, the labels' pose and mesh
reproducing the object's pixels, contacts against trimesh's exact distances, jobs that round-trip and bad jobs
refused in one line."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from object_catalog import SPHERE_RADIUS, toy_items

from darthand.dataset.jobs import check_jobs, validate_jobs
from darthand.errors import InputError
from darthand.render.api import Renderer, render_subject
from darthand.render.assets import HandAssets
from darthand.render.contacts import CONTACT_M
from darthand.render.labels import instance_map, keypoint_names
from darthand.render.lights import load_lighting
from darthand.render.objects import ObjectLibrary
from darthand.render.scene import Scene as TraceScene
from darthand.render.scenes import Scene
from darthand.render.subject import Subject

SIZE = 96


@pytest.fixture(scope="module")
def library():
    return ObjectLibrary(toy_items())


@pytest.fixture(scope="module")
def renderer(hand, texture_files, library):
    source = HandAssets(hand, {texture_files.id: texture_files}, texture_files.id, {}, "open+wrist")
    return Renderer(source, 2, objects=library)


def placement(shift, rotation=None) -> list:
    P = np.eye(4)
    P[:3, :3] = np.eye(3) if rotation is None else rotation
    P[:3, 3] = shift
    return P.tolist()


def object_job(obj: str, where: list, camera="three_quarter", pose="flat") -> dict:
    return {"bodies": [{"kind": "hand", "pose": pose}, {"kind": "object", "object": obj, "placement": where}],
            "camera": camera}


def render(renderer, job: dict):
    return renderer.render_scene(Scene.from_job(job), width=SIZE, height=SIZE, samples=4)


def camera_of(frame) -> dict:
    return {"K": frame.labels["K"], "R": frame.labels["camera"]["R"], "t": frame.labels["camera"]["t"],
            "width": SIZE, "height": SIZE}


def object_alone(frame):
    """(drawn (H, W) bool, depth (H, W)) of the frame's object rendered with nothing else, by the same camera."""
    held = frame.subject.objects[0]
    subject = Subject(held.surfaces, np.zeros((16, 3)), np.zeros((21, 3)), "right", np.zeros(48))
    alone = render_subject(subject, TraceScene(subject), frame.camera, load_lighting(None), samples=1, labels=False)
    drawn = alone.geom >= 0
    return drawn, np.where(drawn, alone.depth, np.inf)


@pytest.fixture(scope="module")
def flat_hand(renderer):
    """The flat hand's vertices and keypoints (world), rendered alone."""
    frame = renderer.render_scene(Scene.from_job({"pose": "flat"}), width=SIZE, height=SIZE, samples=1)
    return frame.subject.hand_vertices.astype(np.float64), np.asarray(frame.labels["keypoints_3d_world"])


def test_an_object_job_round_trips_and_is_checked(library):
    job = object_job("ball_01", placement((0.01, -0.05, 0.02)))
    job["grasp"] = {"type": "power_sphere", "id": "ball_01/power_sphere/0"}
    assert Scene.from_job(job).to_job() == job
    assert check_jobs([job])[0]["bodies"] == job["bodies"]
    assert [b.kind for b in Scene.from_job(job).bodies] == ["hand", "object"]


def test_the_objects_pixels_are_where_it_is_drawn_alone_and_nearer(renderer, flat_hand):
    vertices, _ = flat_hand
    behind_edge = (vertices[:, 0].mean(), vertices[:, 1].min() - 0.05, vertices[:, 2].max())   # the thumb's side
    frame = render(renderer, object_job("ball_01", placement(behind_edge), "dorsal"))
    camera = camera_of(frame)
    hand_alone = renderer.render_scene(Scene.from_job({"pose": "flat", "camera": camera}), width=SIZE, height=SIZE,
                                       samples=1)
    hand_depth = np.where(hand_alone.geom >= 0, hand_alone.depth, np.inf)
    drawn, depth = object_alone(frame)
    expected = drawn & (depth < hand_depth)
    instances = instance_map(frame.geom, frame.subject)
    got = instances == 3
    assert expected.sum() > 100 and (drawn & ~expected).sum() > 20          # seen, and partly behind the hand
    assert (got == expected).mean() > 0.999
    labels = frame.labels["objects"][0]
    assert labels["instance"] == 3 and labels["id"] == "ball_01" and labels["category"] == "ball"
    assert labels["visible_fraction"] == pytest.approx(expected.sum() / drawn.sum(), abs=2e-3)
    rows, cols = np.nonzero(got)
    assert labels["bbox"] == [cols.min(), rows.min(), cols.max() + 1, rows.max() + 1]
    assert not (frame.alpha[got & (hand_alone.geom < 0)] > 0).any()        # the hand's mask leaves the object out


def test_a_fingertip_behind_the_object_is_hidden(renderer, flat_hand):
    _, keypoints = flat_hand
    tip = keypoint_names("openpose").index("index4")
    in_front = keypoints[tip] + (0.0, -(SPHERE_RADIUS + 0.02), 0.0)          # on the palm's side, 2 cm clear of it
    frame = render(renderer, object_job("ball_01", placement(in_front), "palmar"))
    alone = renderer.render_scene(Scene.from_job({"pose": "flat", "camera": camera_of(frame)}), width=SIZE,
                                  height=SIZE, samples=1)
    assert alone.labels["visibility"][tip]
    visible = frame.labels["hands"][0]["visibility"]
    assert not visible[tip]
    assert visible[0] == alone.labels["visibility"][0]                      # the wrist is not behind the ball
    assert frame.labels["objects"][0]["contacts"]["hand_vertices"] == []


def test_the_labels_pose_and_mesh_reproduce_the_objects_pixels(renderer, library):
    rotation = trimesh.transformations.rotation_matrix(0.7, (1, 0, 1))[:3, :3]
    frame = render(renderer, object_job("bottle_01", placement((-0.04, -0.07, 0.03), rotation), "radial"))
    labels = frame.labels["objects"][0]
    item = library.item("bottle_01")
    R, t, K = np.asarray(labels["pose"]["R"]), np.asarray(labels["pose"]["t"]), np.asarray(frame.labels["K"])
    camera_points = item.vertices @ R.T + t
    uv = camera_points @ K.T
    uv = uv[:, :2] / uv[:, 2:]
    drawn, _ = object_alone(frame)
    covered = rasterise(uv, item.faces, SIZE)
    assert drawn.sum() > 200
    assert (covered != drawn).sum() <= 0.002 * drawn.sum() + 2
    corners = np.asarray(labels["corners_3d"]) @ K.T
    assert np.allclose(corners[:, :2] / corners[:, 2:], labels["corners_2d"], atol=1e-9)
    box = np.asarray(labels["corners_3d"])
    lo, hi = item.vertices.min(axis=0), item.vertices.max(axis=0)
    assert np.allclose(np.sort(np.linalg.norm(box - box[0], axis=1))[-1], np.linalg.norm(hi - lo))


def rasterise(uv: np.ndarray, faces: np.ndarray, size: int) -> np.ndarray:
    """(size, size) bool: pixel centres inside any projected triangle (uv (N, 2) pixels, faces (F, 3))."""
    rows, cols = np.mgrid[0:size, 0:size]
    p = np.stack([cols + 0.5, rows + 0.5], axis=-1).reshape(-1, 2)
    out = np.zeros(len(p), bool)
    for a, b, c in uv[faces]:
        e = [(b - a, p - a), (c - b, p - b), (a - c, p - c)]
        s = np.stack([u[0] * w[:, 1] - u[1] * w[:, 0] for u, w in e])
        out |= (s >= 0).all(axis=0) | (s <= 0).all(axis=0)
    return out.reshape(size, size)


@pytest.mark.parametrize("depth, touching", [(0.006, True), (-0.02, False)])
def test_contacts_are_the_hand_vertices_near_or_inside_the_object(renderer, library, flat_hand, depth, touching):
    vertices, _ = flat_hand
    x, z = vertices[:, 0].mean(), vertices[:, 2].mean()
    palm = vertices[np.hypot(vertices[:, 0] - x, vertices[:, 2] - z) < 0.01]       # the palm's middle
    centre = (x, palm[:, 1].min() - SPHERE_RADIUS + depth, z)
    frame = render(renderer, object_job("ball_01", placement(centre)))
    labels = frame.labels["objects"][0]
    mesh = trimesh.Trimesh(library.item("ball_01").vertices, library.item("ball_01").faces, process=False)
    local = vertices - centre
    nearest, distance, _ = trimesh.proximity.closest_point_naive(mesh, local)
    inside = mesh.contains(local)
    expected = np.flatnonzero((distance <= CONTACT_M) | inside)
    assert labels["contacts"]["hand_vertices"] == expected.tolist()
    assert bool(len(expected)) == touching
    if touching:
        points = np.asarray(labels["contacts"]["object_points"])
        reach = np.linalg.norm(points - local[expected], axis=1)
        assert np.allclose(reach, distance[expected], atol=1e-9)     # as near as the nearest point (ties may differ)
        assert np.abs(points - nearest[expected]).max() < 1e-5
        assert labels["penetration_max_mm"] == pytest.approx(1000 * distance[inside].max(), abs=1e-3)
    else:
        assert labels["penetration_max_mm"] == 0


def test_bad_object_jobs_are_refused_in_one_line(renderer, library, flat_hand):
    sources = {"right": renderer.source}
    good = check_jobs([object_job("ball_01", placement((0.0, 0.2, 0.0)))])
    validate_jobs(sources, good, objects=library)
    with pytest.raises(InputError, match=r"object 'mug_99' is not in the object catalogue$"):
        validate_jobs(sources, check_jobs([object_job("mug_99", placement((0.0, 0.2, 0.0)))]), objects=library)
    sheared = np.eye(4)
    sheared[0, 1] = 0.3
    with pytest.raises(InputError, match=r"bodies\.1\.placement' is not a rigid transform"):
        check_jobs([object_job("ball_01", sheared.tolist())])
    vertices, _ = flat_hand
    through = placement(vertices.mean(axis=0))
    with pytest.raises(InputError, match=r"frame 0: the right hand passes into object 'ball_01' \(\d+\.\d mm deep\)"):
        validate_jobs(sources, check_jobs([object_job("ball_01", through)]), objects=library)
    with pytest.raises(InputError, match=r"needs an object catalogue"):
        Renderer(renderer.source).render_scene(Scene.from_job(object_job("ball_01", through)), width=SIZE,
                                               height=SIZE)
