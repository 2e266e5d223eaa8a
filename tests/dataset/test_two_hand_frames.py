"""Two-hand dataset frames (issue 29): a jobs file of `bodies` through `render-dataset --jobs` end to end (per-hand
labels valid against the schema, MANO camera parameters whose forward pass gives each hand's keypoints and mesh,
the instance map), the jobs round trip, and bad two-hand jobs as one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers_dataset import SIZE, files_of

from darthand.cli import main
from darthand.dataset.jobs import load_jobs
from darthand.model.forward import forward
from darthand.render.image import read_png
from darthand.render.scenes import Scene
from darthand.schemas import check_schema

JOBS = Path(__file__).with_name("two_hand_jobs.json")


def _cli(package, *args):
    model, tex, acc = package
    return ["render-dataset", model, "--textures", tex, "--accessories", acc, "--size", str(SIZE), "--samples",
            "4", "--processes", "1", *args]


def test_the_example_jobs_round_trip_through_the_scene_model():
    jobs = load_jobs(JOBS)
    assert [len(Scene.from_job(j).bodies) for j in jobs] == [2, 2, 2, 1]
    for job in jobs:
        assert Scene.from_job(job).to_job() == job
    placed = Scene.from_job(jobs[0]).bodies[1]
    assert placed.side == "left" and np.allclose(placed.placement_matrix()[:3, 3], [0, -0.07, -0.06])


@pytest.fixture(scope="module")
def two_hand_dataset(package, tmp_path_factory):
    out = tmp_path_factory.mktemp("two-hands")
    assert main([*_cli(package, "--jobs", str(JOBS), "--out", str(out))]) == 0
    return out


def test_a_two_hand_jobs_file_renders_labelled_frames(two_hand_dataset, sources):
    out, (opened, _) = two_hand_dataset, sources
    jobs = {j["index"]: j for j in load_jobs(JOBS)}
    for index in (0, 1, 2):
        labels = json.loads((out / "labels" / f"{index:06d}.json").read_text())
        check_schema(labels, "labels.schema.json", f"frame {index}")
        assert labels["hand_type"] == "interacting" and labels["interaction"] == jobs[index]["interaction"]
        assert "side" not in labels and "keypoints_3d" not in labels and "mano" not in labels
        meshes = np.load(out / "labels" / labels["files"]["vertices"])
        instances = read_png(out / "labels" / labels["files"]["instances"])
        assert meshes.shape[0] == 2 and meshes.dtype == np.float32 and instances.shape[:2] == (SIZE, SIZE)
        mask = read_png(out / "labels" / labels["files"]["mask"])
        assert ((instances.reshape(SIZE, SIZE, -1)[..., 0] > 0) <= (mask.reshape(SIZE, SIZE, -1)[..., 0] > 0)).all()
        for b, hand in enumerate(labels["hands"]):
            assert hand["side"] == ("right", "left")[b] and hand["instance"] == {"hand": 1 + 2 * b,
                                                                                 "accessory": 2 + 2 * b}
            mano = hand["mano"]
            posed = forward(opened[hand["side"]].model, np.concatenate([mano["global_orient"],
                                                                         mano["hand_pose"]])[None],
                            mano["betas"], trans=np.asarray(mano["trans"])[None], keypoint_order="openpose")
            assert np.abs(posed.keypoints[0] - hand["keypoints_3d"]).max() < 2e-6     # float32 render vs float64
            assert np.abs(posed.vertices[0] - meshes[b]).max() < 5e-6
            K = np.asarray(labels["K"])
            uv = np.asarray(hand["keypoints_3d"]) @ K.T
            assert np.allclose(uv[:, :2] / uv[:, 2:], hand["keypoints_2d"], atol=1e-6)
            assert hand["mesh"]["vertices"] == meshes.shape[1]
    touching = json.loads((out / "labels" / "000000.json").read_text())["hands"]
    apart = json.loads((out / "labels" / "000001.json").read_text())["hands"]
    assert touching[0]["contacts"] and touching[1]["contacts"] and not apart[0]["contacts"]
    assert touching[1]["accessory"]["id"] == "ring_test" and "worn" in touching[1]["accessory"]
    overlapped = json.loads((out / "labels" / "000002.json").read_text())["hands"]
    assert sum(overlapped[0]["visibility"]) < sum(overlapped[1]["visibility"])   # the right hand is behind
    one = json.loads((out / "labels" / "000003.json").read_text())                   # a one-hand job: as before
    assert one["side"] == "left" and "hands" not in one and "instances" not in one["files"]
    assert np.load(out / "labels" / one["files"]["vertices"]).ndim == 2
    assert not (out / "instances" / "000003.png").exists()


def test_a_two_hand_run_resumes_without_rendering_again(package, two_hand_dataset, capsys):
    assert main([*_cli(package, "--jobs", str(JOBS), "--out", str(two_hand_dataset))]) == 0
    doc = json.loads((two_hand_dataset / "dataset.json").read_text())
    assert doc["rendered"] == 0 and doc["count"] == 4


@pytest.mark.slow
def test_two_worker_processes_write_the_same_two_hand_frames(package, two_hand_dataset, tmp_path):
    """Spawned workers open both sides' sources for a two-hand job (dataset/local.job_renderer): same bytes."""
    args = _cli(package, "--jobs", str(JOBS), "--out", str(tmp_path))
    args[args.index("--processes") + 1] = "2"
    assert main(args) == 0
    assert files_of(tmp_path) == files_of(two_hand_dataset)


HAND = {"kind": "hand", "side": "left"}


@pytest.mark.parametrize("job, expected", [
    ({"pose": "fist", "bodies": [HAND]}, "field 'frames.0' holds both 'bodies' and the one-hand field 'pose'"),
    ({"bodies": [{"kind": "cup"}]}, "field 'frames.0.bodies.0.kind' 'cup' is not a body kind (known: hand, object)"),
    ({"bodies": [{**HAND, "placement": [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}]},
     "field 'frames.0.bodies.0.placement' is not a rigid transform"),
    ({"bodies": [{**HAND, "placement": [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}]},
     "field 'frames.0.bodies.0.placement' is not a rigid transform"),
    ({"bodies": [{**HAND, "placement": [[1, 0, 0], [0, 1, 0]]}]}, "is not a 4x4 matrix"),
    ({"bodies": [HAND, HAND, HAND]}, "field 'frames.0.bodies'"),
    ({"bodies": [{**HAND, "texture": "light_nope_00"}]}, "frame 0: bodies.0: texture 'light_nope_00' is not in"),
    ({"bodies": [HAND], "interaction": {"type": "hugging"}}, "field 'frames.0.interaction.type'"),
    ({"bodies": [{**HAND, "side": "right"}, {**HAND, "placement": [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 0],
                                                               [0, 0, 0, 1]]}]},
     "frame 0: the two hands pass through each other"),
])
def test_bad_two_hand_jobs_are_one_line_errors(package, tmp_path, capsys, job, expected):
    (tmp_path / "jobs.json").write_text(json.dumps({"frames": [job]}))
    rc = main([*_cli(package, "--jobs", str(tmp_path / "jobs.json"), "--out", str(tmp_path / "out"))])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and err.startswith("darthand: error: ") and expected in err, err


def test_a_one_body_bodies_job_is_the_one_hand_job(sources, tmp_path):
    """The bodies form of one hand without a placement renders and labels exactly as the top-level form."""
    from darthand.dataset.frames import render_job, write_dataset_frame
    from darthand.render.api import Renderer

    opened, _ = sources
    hand = {"side": "left", "pose": "fist", "betas": [0.5], "skin_tone_offset": 0.05, "accessory": "ring_test"}
    settings = {"size": SIZE, "samples": 4, "aa_shading": "triangle", "out_dir": str(tmp_path)}
    written = []
    for k, job in enumerate(({"index": 0, **hand}, {"index": 0, "bodies": [{"kind": "hand", **hand}]})):
        renderer = Renderer(opened["left"], 1, opened)
        frame, background = render_job(renderer, job, settings)
        write_dataset_frame(frame, job, "digest", tmp_path / str(k), renderer.source, background, renderer.sources)
        written.append(files_of(tmp_path / str(k)))
    assert written[0] == written[1] and "instances/000000.png" not in written[0]
