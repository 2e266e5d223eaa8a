"""Dataset frames of a hand holding an object (hand-written jobs with an object body, a catalogue of trimesh
primitives): the frame's files (instance map, object mesh), HO-3D's layout read back by its conventions (its joints
projected with camMat onto the labels' 2-D points, its MANO parameters posed back into its joints, the object's
corners), WebDataset's reader, the report's counts."""

from __future__ import annotations

import io
import pickle
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "render"))
from object_catalog import SPHERE_RADIUS, write_catalog  # noqa: E402

from darthand.cli import main  # noqa: E402
from darthand.dataset.options import DatasetOptions  # noqa: E402
from darthand.dataset.report_objects import object_counts  # noqa: E402
from darthand.dataset.run import render_frames, rendered_dataset  # noqa: E402
from darthand.fileio import read_json  # noqa: E402
from darthand.model.forward import forward  # noqa: E402
from darthand.model.layout import KEYPOINT_ORDERS  # noqa: E402
from darthand.model.rotations import axis_angle_to_matrix  # noqa: E402
from darthand.objects.loader import load_object_catalog  # noqa: E402
from darthand.render.image import read_png  # noqa: E402

SIZE = 64
C = np.diag([1.0, -1.0, -1.0])          # HO-3D's coordChangeMat: OpenGL <-> OpenCV camera frames


def placement(shift) -> list:
    P = np.eye(4)
    P[:3, 3] = shift
    return P.tolist()


@pytest.fixture(scope="module")
def object_dataset(hand, sources, tmp_path_factory):
    """(dataset folder, catalogue path): frame 0 the flat right hand touching the ball with its palm (train),
    frame 1 the right fist beside the bottle (test), frame 2 a left hand with the box, frame 3 one hand alone."""
    opened, specs = sources
    root = tmp_path_factory.mktemp("objects")
    catalog = write_catalog(root / "catalog")
    v = np.asarray(hand.v_template, np.float64)        # the flat hand (flat_hand_mean: pose 0)
    x, z = v[:, 0].mean(), v[:, 2].mean()
    palm = v[np.hypot(v[:, 0] - x, v[:, 2] - z) < 0.01]
    touching = (x, palm[:, 1].min() - SPHERE_RADIUS - 0.001, z)
    jobs = [{"index": 0, "split": "train", "camera": "palmar", "grasp": {"type": "power_sphere", "id": "ball_01/x/0"},
             "bodies": [{"kind": "hand", "side": "right", "pose": "flat"},
                        {"kind": "object", "object": "ball_01", "placement": placement(touching)}]},
            {"index": 1, "split": "test", "camera": "radial",
             "bodies": [{"kind": "hand", "side": "right", "pose": "fist"},
                        {"kind": "object", "object": "bottle_01", "placement": placement((-0.05, -0.08, 0.05))}]},
            {"index": 2, "split": "train",
             "bodies": [{"kind": "hand", "side": "left", "pose": "flat"},
                        {"kind": "object", "object": "box_01", "placement": placement((0.05, -0.1, 0.0))}]},
            {"index": 3, "split": "train", "side": "right", "pose": "fist"}]
    out = root / "dataset"
    options = DatasetOptions(specs["right"].package, str(out), size=SIZE, samples=4, progress=False, processes=1,
                             objects_catalog=str(catalog), maps=("depth",))
    render_frames(options, opened, specs, jobs=jobs)
    return out, catalog


def test_an_object_frame_writes_its_instances_and_object_mesh(object_dataset):
    root, catalog = object_dataset
    labels = read_json(root / "labels" / "000000.json", "labels")
    held = labels["objects"][0]
    assert held["id"] == "ball_01" and held["grasp"] == {"type": "power_sphere", "id": "ball_01/x/0"}
    assert held["contacts"]["hand_vertices"] and held["penetration_max_mm"] == 0
    instances = read_png(root / "instances" / "000000.png")[..., 0]
    assert (instances == 3).sum() > 0 and (instances == 1).sum() > 0
    item = {i.id: i for i in load_object_catalog(catalog)}["ball_01"]
    R, t = np.asarray(held["pose"]["R"]), np.asarray(held["pose"]["t"])
    mesh = np.load(root / "object_meshes" / "000000.npy")
    assert mesh.dtype == np.float32 and np.abs(mesh - (item.vertices @ R.T + t)).max() < 1e-6
    assert not (root / "object_meshes" / "000003.npy").exists()
    _, frames = rendered_dataset(root)
    counts = object_counts(frames)
    assert counts == {"frames": 3, "category": {"ball": 1, "bottle": 1, "box": 1},
                      "grasp_type": {"None": 2, "power_sphere": 1}}


def test_ho3d_layout_reads_back_by_its_conventions(object_dataset, hand, tmp_path):
    root, catalog = object_dataset
    out = tmp_path / "ho3d"
    assert main(["dataset", "export", str(root), "--format", "ho3d", "--out", str(out)]) == 0
    assert (out / "train.txt").read_text() == "DH/000000\nDH/000002\n"      # the bare hand out, the left mirrored
    assert (out / "evaluation.txt").read_text() == "DH/000001\n"
    for folder, frame in (("train", 0), ("evaluation", 1)):
        labels = read_json(root / "labels" / f"{frame:06d}.json", "labels")
        hand_labels = labels["hands"][0]
        meta = pickle.loads((out / folder / "DH" / "meta" / f"{frame:06d}.pkl").read_bytes())
        # HO-3D's projection: OpenGL points turned by coordChangeMat, then camMat (pixel centres at integers)
        uvw = np.asarray(meta["handJoints3D"], np.float64) @ C.T @ np.asarray(meta["camMat"], np.float64).T
        expected = np.empty((21, 2))
        expected[KEYPOINT_ORDERS[labels["keypoint_order"]]] = np.asarray(hand_labels["keypoints_2d"]) - 0.5
        assert np.abs(uvw[:, :2] / uvw[:, 2:] - expected).max() < 1e-3
        # MANO posed with handPose, handBeta, handTrans gives handJoints3D (the right model, flat hand mean)
        posed = forward(hand, meta["handPose"].astype(np.float64), meta["handBeta"].astype(np.float64),
                        trans=meta["handTrans"].astype(np.float64))
        assert np.abs(posed.keypoints[0] - meta["handJoints3D"]).max() < 1e-5
        # the object: corners at rest moved by objRot, objTrans, projected onto the labels' corners
        R = np.asarray(axis_angle_to_matrix(meta["objRot"].reshape(3).astype(np.float64))).reshape(3, 3)
        corners = meta["objCorners3DRest"] @ R.T + meta["objTrans"]
        assert np.abs(corners - meta["objCorners3D"]).max() < 1e-5
        uvw = corners @ C.T @ np.asarray(meta["camMat"], np.float64).T
        assert np.abs(uvw[:, :2] / uvw[:, 2:] - (np.asarray(labels["objects"][0]["corners_2d"]) - 0.5)).max() < 1e-2
        assert meta["objName"] == labels["objects"][0]["id"]
        seg = read_png(out / folder / "DH" / "seg" / f"{frame:06d}.png")
        instances = read_png(root / "instances" / f"{frame:06d}.png")[..., 0]
        assert ((seg[..., 1] == 255) == (instances == 3)).all() and ((seg[..., 2] == 255) == (instances == 1)).all()
        depth = read_png(out / folder / "DH" / "depth" / f"{frame:06d}.png").astype(np.float64)
        metres = (depth[..., 0] + 256 * depth[..., 1]) * 0.00012498664727900177
        seen = instances == 3
        z = np.asarray(labels["objects"][0]["corners_3d"])[:, 2]
        assert (metres[seen] > z.min() - 0.01).all() and (metres[seen] < z.max() + 0.01).all()
    contact = pickle.loads((out / "train" / "DH" / "meta" / "000000.pkl").read_bytes())["handVertContact"]
    ids = read_json(root / "labels" / "000000.json", "labels")["objects"][0]["contacts"]["hand_vertices"]
    assert sorted(np.flatnonzero(contact).tolist()) == [i for i in ids if i < 778]


def test_webdataset_carries_the_object(object_dataset, tmp_path):
    import webdataset as wds

    root, _ = object_dataset
    assert main(["dataset", "export", str(root), "--format", "webdataset", "--out", str(tmp_path)]) == 0
    urls = sorted(str(p) for p in tmp_path.glob("*.tar"))
    seen = {}
    for sample in wds.WebDataset(urls, shardshuffle=False):
        seen[sample["__key__"]] = sample
    assert set(seen) == {"000000", "000001", "000002", "000003"}
    for key in ("000000", "000001", "000002"):
        mesh = np.load(io.BytesIO(seen[key]["object.npy"]))
        assert np.array_equal(mesh, np.load(root / "object_meshes" / f"{key}.npy"))
        assert "instances.png" in seen[key]
    assert "object.npy" not in seen["000003"]


def test_ho3d_writes_a_left_hand_mirrored_by_its_conventions(object_dataset, hand, tmp_path):
    """A left hand's object frame in HO-3D's layout is its mirror image, read by HO-3D's conventions: the written
    joints projected with camMat onto the labels' 2-D keypoints flipped, MANO's RIGHT model posed with the written
    parameters into the written joints, the object's corners posed and projected onto the flipped object mask; the
    images are the frame's flipped. --left skip leaves it out."""
    root, _ = object_dataset
    out = tmp_path / "ho3d"
    assert main(["dataset", "export", str(root), "--format", "ho3d", "--out", str(out)]) == 0
    labels = read_json(root / "labels" / "000002.json", "labels")
    hand_labels = labels["hands"][0]
    assert hand_labels["side"] == "left"
    width = labels["image_size"][0]
    meta = pickle.loads((out / "train" / "DH" / "meta" / "000002.pkl").read_bytes())
    assert meta["flipped"] is True
    assert "flipped" not in pickle.loads((out / "train" / "DH" / "meta" / "000000.pkl").read_bytes())
    cam = np.asarray(meta["camMat"], np.float64)
    uvw = np.asarray(meta["handJoints3D"], np.float64) @ C.T @ cam.T
    seen = np.asarray(hand_labels["keypoints_2d"]) - 0.5                 # pixel centres at integers
    flipped = np.column_stack([width - 1 - seen[:, 0], seen[:, 1]])
    expected = np.empty((21, 2))
    expected[KEYPOINT_ORDERS[labels["keypoint_order"]]] = flipped
    assert np.abs(uvw[:, :2] / uvw[:, 2:] - expected).max() < 1e-3
    # the RIGHT model posed with the written parameters is the written hand
    posed = forward(hand, meta["handPose"].astype(np.float64), meta["handBeta"].astype(np.float64),
                    trans=meta["handTrans"].astype(np.float64))
    assert np.abs(posed.keypoints[0] - meta["handJoints3D"]).max() < 1e-5
    # ... whose vertices, taken back to the OpenCV frame and mirrored, are the frame's left hand's mesh
    mesh = np.load(root / "meshes" / "000002.npy").reshape(-1, 3)
    back = np.asarray(posed.vertices[0]) @ C.T * [-1.0, 1.0, 1.0]
    assert np.abs(back - mesh[:len(back)]).max() < 1e-5
    # the object: its corners at rest posed by objRot, objTrans, projected onto the flipped object mask
    R = np.asarray(axis_angle_to_matrix(meta["objRot"].reshape(3).astype(np.float64))).reshape(3, 3)
    assert np.linalg.det(R) > 0.999
    corners = meta["objCorners3DRest"] @ R.T + meta["objTrans"]
    assert np.abs(corners - meta["objCorners3D"]).max() < 1e-5
    uvw = corners @ C.T @ cam.T
    uv = uvw[:, :2] / uvw[:, 2:]
    seg = read_png(out / "train" / "DH" / "seg" / "000002.png")
    rows, cols = np.nonzero(seg[..., 1] == 255)
    assert len(rows) > 20
    assert cols.min() >= uv[:, 0].min() - 1 and cols.max() <= uv[:, 0].max() + 1
    assert rows.min() >= uv[:, 1].min() - 1 and rows.max() <= uv[:, 1].max() + 1
    verts = np.asarray(meta["objVertices3D"], np.float64) @ C.T @ cam.T
    px = verts[:, :2] / verts[:, 2:]
    assert abs(np.median(px[:, 0]) - np.median(cols)) < 3 and abs(np.median(px[:, 1]) - np.median(rows)) < 3
    # the images: the frame's, flipped left-right
    instances = read_png(root / "instances" / "000002.png")[..., 0][:, ::-1]
    assert ((seg[..., 1] == 255) == (instances == 3)).all() and ((seg[..., 2] == 255) == (instances == 1)).all()
    image = read_png(root / "images" / "000002.png")
    rgb = read_png(out / "train" / "DH" / "rgb" / "000002.png")
    alpha = image[..., 3:4].astype(np.float64) / 255
    assert (np.abs(rgb.astype(int) - np.round(image[..., :3] * alpha)[:, ::-1]) <= 1).all()

    skipped = tmp_path / "ho3d_skip"
    assert main(["dataset", "export", str(root), "--format", "ho3d", "--out", str(skipped), "--left", "skip"]) == 0
    assert (skipped / "train.txt").read_text() == "DH/000000\n"
