"""Rendering datasets: the same bytes over 1 or 2 processes, labels against the forward pass (MANO parameters in
the camera frame, the mesh), resume by shard records and digests, one-line errors for bad input, interrupted runs
(SIGINT, SIGKILL) leave no orphans or leftovers and resume to the same bytes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers_dataset import SIZE, BakedPackage, files_of, render

from darthand.cli import main
from darthand.dataset import run
from darthand.dataset.options import DatasetOptions
from darthand.errors import InputError
from darthand.model.forward import forward
from darthand.render.source import FrameSource
from darthand.schemas import check_schema


def test_two_processes_write_the_same_bytes_as_one(planner, sources, small_dataset, tmp_path):
    one, doc = small_dataset
    two = render(planner, sources, tmp_path, 16, processes=2, shard_size=8, chunk_size=1)
    assert doc["rendered"] == two["rendered"] == 16 and two["timings"]["processes"] == 2
    a, b = files_of(one), files_of(tmp_path)
    assert len(a) == 16 * 4 + 2 and a == b                       # images, masks, labels, meshes; two shard records
    assert doc["summary"] == two["summary"] and sum(doc["summary"]["counts"]["side"].values()) == 16
    assert len(two["timings"]["worker_peak_rss_mb"]) == 2 and "primary" in two["timings"]["steps_ms"]


def test_labels_match_the_forward_pass_in_the_camera_frame(small_dataset, sources):
    out, _ = small_dataset
    opened, _ = sources
    rings = 0
    for path in sorted((out / "labels").iterdir()):
        labels = json.loads(path.read_text())
        check_schema(labels, "labels.schema.json", path.name)
        model = opened[labels["side"]].model
        mano = labels["mano"]
        posed = forward(model, np.concatenate([mano["global_orient"], mano["hand_pose"]])[None], mano["betas"],
                        trans=np.asarray(mano["trans"])[None], keypoint_order="openpose")
        assert np.abs(posed.keypoints[0] - labels["keypoints_3d"]).max() < 2e-6     # float32 render vs float64
        assert np.abs(posed.joints[0] - labels["joints_3d"]).max() < 2e-6
        vertices = np.load(path.parent / labels["files"]["vertices"])
        assert vertices.dtype == np.float32 and np.abs(posed.vertices[0] - vertices).max() < 5e-6
        assert labels["mesh"]["base_vertices"] == model.meta["wrist"]["base_vertices"] < len(vertices)
        K = np.asarray(labels["K"])
        uv = (np.asarray(labels["keypoints_3d"]) @ K.T)
        assert np.allclose(uv[:, :2] / uv[:, 2:], labels["keypoints_2d"], atol=1e-6)
        assert labels["sample"]["pose"]["mode"] == "dart" and labels["split"] in ("train", "val", "test")
        assert labels["render"]["background"]["used"].startswith("environment:")             # the default backdrop
        assert all(labels["in_image"])                                            # the hand kept in frame
        worn = labels["accessory"].get("worn")
        assert (worn is not None) == (labels["accessory"]["id"] == "ring_test")   # rings are worn per pose
        rings += worn is not None
    assert rings


def test_ring_frames_digest_how_rings_are_worn(planner, monkeypatch):
    """Ring frames rendered before rings were worn per pose (or by another version of it) are rendered again on
    resume; other frames keep their digests."""
    from darthand.dataset import frames

    jobs = list(planner.jobs(0, 16))
    ring = next(j for j in jobs if j["accessory"] == "ring_test")
    other = next(j for j in jobs if j["accessory"] != "ring_test")
    settings = {"size": 64, "samples": 4, "aa_shading": "triangle"}
    before = [frames.job_digest(j, settings) for j in (ring, other)]
    monkeypatch.setattr(frames, "RING_WEAR", frames.RING_WEAR + 1)
    after = [frames.job_digest(j, settings) for j in (ring, other)]
    assert before[0] != after[0] and before[1] == after[1]


def test_resume_skips_shards_and_frames_already_rendered(planner, sources, tmp_path):
    render(planner, sources, tmp_path, 6, shard_size=4)
    stamps = {p: p.stat().st_mtime_ns for p in (tmp_path / "labels").iterdir()}
    again = render(planner, sources, tmp_path, 6, shard_size=4)
    assert (again["rendered"], again["skipped"]) == (0, 6)
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    (tmp_path / "masks" / "000001.png").unlink()                                  # an interrupted frame
    (tmp_path / "labels" / ".000005.json.tmp123.json").write_text("{")            # a temporary file left behind
    third = render(planner, sources, tmp_path, 6, shard_size=4)
    assert (third["rendered"], third["skipped"]) == (1, 5)
    assert not list((tmp_path / "labels").glob(".*"))
    forced = render(planner, sources, tmp_path, 6, shard_size=4, resume=False)
    assert forced["rendered"] == 6


def test_a_failing_frame_stops_the_run_with_its_index(package, sources, tmp_path):
    opened, specs = sources
    bad = tmp_path / "pose.json"
    bad.write_text('{"pose": [' + ",".join(["0"] * 48) + "]}")
    jobs = [{"index": 0, "pose": "fist"}, {"index": 7, "pose": str(bad)}]
    from darthand.dataset.jobs import check_jobs, validate_jobs

    validate_jobs(opened, check_jobs(jobs))
    bad.write_text("{not json")                                           # broken by the time it renders
    with pytest.raises(InputError, match=r"^frame 7: .*pose.json: not valid JSON"):
        run.render_frames(DatasetOptions(package[0], str(tmp_path / "out"), jobs=jobs, processes=1, size=SIZE,
                                         samples=4, progress=False), opened, specs)


def _cli(package, *args):
    model, tex, acc = package
    return [model, "--textures", tex, "--accessories", acc, "--size", str(SIZE), "--samples", "4", *args]


def test_cli_plans_renders_and_a_written_plan_renders_the_same(package, tmp_path, capsys):
    common = _cli(package, "--processes", "1", "--count", "3", "--seed", "11", "--pose-mode", "jitter",
                  "--gestures", "fist,point", "--views", "dorsal,random", "--skin-tone-range=-0.05,0.05")
    assert main(["render-dataset", *common, "--out", str(tmp_path / "a"), "--formats", "freihand",
                 "--allow-non-mano"]) == 0
    assert "3 frames rendered" in capsys.readouterr().out
    assert "ZERO" in (tmp_path / "a" / "freihand" / "README.md").read_text()    # the open hand: no MANO shape
    assert main(["render-dataset", *common, "--out", str(tmp_path / "unused"), "--plan",
                 str(tmp_path / "jobs.json")]) == 0
    assert not (tmp_path / "unused").exists()
    assert main(["render-dataset", *_cli(package, "--processes", "1", "--jobs", str(tmp_path / "jobs.json"),
                                         "--out", str(tmp_path / "b"))]) == 0
    frames = lambda d: {k: v for k, v in files_of(d).items()  # noqa: E731
                        if not k.startswith(("shards", "freihand"))}
    assert frames(tmp_path / "a") == frames(tmp_path / "b")
    doc = json.loads((tmp_path / "a" / "dataset.json").read_text())
    assert doc["jobs"]["plan"]["seed"] == 11 and doc["count"] == 3 and doc["rendered"] == 3
    labels = [json.loads(p.read_text()) for p in sorted((tmp_path / "a" / "labels").iterdir())]
    assert {lab["gesture"] for lab in labels} <= {"fist", "point"}


def test_shading_options_reach_the_frames_and_their_resume_digest(package, tmp_path, capsys):
    args = _cli(package, "--processes", "1", "--count", "1", "--out", str(tmp_path))
    args = [*args, "--skin-specular", "dual", "--shadows", "vertex"]
    assert main(["render-dataset", *args, "--ao-rays", "0", "--skin", "lambert"]) == 0
    labels = json.loads((tmp_path / "labels" / "000000.json").read_text())
    expected = {"ao_rays": 0, "interreflection": True, "skin": "lambert", "skin_specular": "dual",
                "shadows": "vertex"}
    assert labels["render"]["shading"] == expected                  # no relief: a dataset's default
    assert json.loads((tmp_path / "dataset.json").read_text())["shading"] == expected
    unblocked = (tmp_path / "images" / "000000.png").read_bytes()
    assert main(["render-dataset", *args, "--ao-rays", "0", "--skin", "lambert"]) == 0
    assert "0 frames rendered, 1 already there" in capsys.readouterr().out
    assert main(["render-dataset", *args, "--ao-rays", "8", "--skin", "lambert"]) == 0     # another digest
    assert "1 frames rendered" in capsys.readouterr().out
    assert (tmp_path / "images" / "000000.png").read_bytes() != unblocked


@pytest.mark.parametrize("args, expected", [
    # numeric options: the CLI's shared `number` type (cli.number / cli.numbers), as every command's
    (["--count", "-1"], "argument --count: -1 is outside [0, 2147483647]"),
    (["--count", "2000000"], "frame budget; --max-frames raises it"),
    (["--count", "0"], None),
    (["--count", "1e3"], "argument --count: '1e3' is not an integer"),
    (["--processes", "0"], "argument --processes: 0 is outside [1, 100000]"),
    (["--processes", "300"], "processes: 300 is outside 1..256"),                # this machine's bound, not Ray's
    (["--threads", "-3"], "argument --threads: -3 is outside [1, 256]"),
    (["--size", "0"], "argument --size: 0 is outside [8, 4096]"),
    (["--size", "100000"], "argument --size: 100000 is outside [8, 4096]"),
    (["--seed", "-1"], "argument --seed: -1 is outside"),
    (["--accessory-share", "nan"], "argument --accessory-share: nan is not a finite number"),
    (["--accessory-share", "1.5"], "argument --accessory-share: 1.5 is outside [0, 1]"),
    (["--pose-jitter", "inf"], "argument --pose-jitter: inf is not a finite number"),
    (["--max-reference-mb", "0"], "argument --max-reference-mb: 0 is outside (0, 1000000]"),
    (["--shape-sigma", "-1"], "argument --shape-sigma: -1 is outside (0, 100]"),
    (["--grid-levels", "1"], "argument --grid-levels: 1 is outside [2, 16]"),
    (["--skin-tone-range=nan,0.1"], "argument --skin-tone-range: nan is not a finite number"),
    (["--skin-tone-range=-0.1"], "argument --skin-tone-range: '-0.1' is not 2 comma-separated numbers"),
    (["--fov-range", "60,30"], "argument --fov-range: 60,30 is not ordered (LO <= HI)"),
    (["--roll-range=-200,0"], "argument --roll-range: -200 is outside [-180, 180]"),
    (["--distance-range", "0.3,inf"], "argument --distance-range: inf is not a finite number"),
    (["--split", "0.8,0.2"], "argument --split: '0.8,0.2' is not 3 comma-separated numbers"),
    (["--split", "0.8,0.2,0.1"], "sums to 1.1, more than 1"),
    (["--start", "1000000000000000000000000000000"], "argument --start: 1000000000000000000000000000000 is outside"),
    (["--formats", "freihand"], "is not a MANO model"),                  # refused before rendering, not after
    (["--formats", "yolo"], "--formats: 'yolo' is not one of freihand, webdataset, hamer, coco"),
    (["--texture-ids", "light_moles_00,light_nope_00"], "textures: 'light_nope_00' is not one of"),
    (["--accessory-ids", "watch_99"], "accessories: 'watch_99'"),
    (["--gestures", "wave", "--pose-mode", "jitter"], "'wave' is not a pose of the pose library"),
    (["--gestures", "wave", "--pose-mode", "jitter", "--reference", "gestures"], "'wave' is not a gesture"),
    (["--views", "top"], "views: 'top'"),
    (["--backgrounds", "/nonexistent/folder"], "neither 'builtin'"),
])
def test_bad_options_are_one_line_errors(package, tmp_path, capsys, args, expected):
    rc = main(["render-dataset", *_cli(package, "--out", str(tmp_path / "out"), "--processes", "1", *args)])
    err = capsys.readouterr().err
    if expected is None:                                               # --count 0: an empty dataset, no error
        assert rc == 0 and json.loads((tmp_path / "out" / "dataset.json").read_text())["count"] == 0
        return
    assert rc == 2 and err.count("\n") == 1 and err.startswith("darthand: error: ") and expected in err, err


@pytest.mark.parametrize("case, expected", [
    ("not json", "not valid JSON"),
    ('{"frames": [{"pose": [1, 2]}]}', "field 'frames.0.pose'"),
    ('[{"texture": "light_nope_00"}]', "frame 0: texture 'light_nope_00' is not in"),
    ('[{"index": 3, "accessory": "watch_99"}]', "frame 3: accessory 'watch_99'"),
    ('[{"camera": {"view": "sideways"}}]', "frame 0: camera: field 'view'"),
    ('[{"index": 1}, {"index": 1}]', "repeats the index of job 0"),
    ('[{"index": 1000000000000000000000000000000}]', "index"),
    ('[{"skin_tone_offset": NaN}]', "'0.skin_tone_offset' is nan, not a finite number"),
    ('[{"lights": {"lights": [{"type": "directional", "direction": [0, 0, 1], "intensity": Infinity}]}}]',
     "is inf, not a finite number"),
])
def test_bad_jobs_files_are_one_line_errors(package, tmp_path, capsys, case, expected):
    (tmp_path / "jobs.json").write_text(case)
    rc = main(["render-dataset", *_cli(package, "--jobs", str(tmp_path / "jobs.json"), "--out",
                                       str(tmp_path / "out"))])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and err.startswith("darthand: error: ") and expected in err, err
    assert not list((tmp_path / "out" / "images").glob("*")) if (tmp_path / "out").exists() else True


def test_a_run_with_a_truncated_background_finishes_and_records_it(package, sources, tmp_path):
    from darthand.dataset.plan import Planner
    from darthand.render.image import write_png

    folder = tmp_path / "bg"
    folder.mkdir()
    write_png(folder / "good.png", np.full((40, 40, 3), 90, np.uint8))
    data = (folder / "good.png").read_bytes()
    (folder / "bad.png").write_bytes(data[:40])
    planner = Planner({"seed": 2, "backgrounds": str(folder), "sides": ["right"]}, sources[0])
    doc = render(planner, sources, tmp_path / "out", 6)
    assert doc["rendered"] == 6 and doc["summary"]["skipped_backgrounds"]["files"] == ["bad.png"]
    assert doc["summary"]["skipped_backgrounds"]["count"] >= 1


def _children(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                found.append(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.parametrize("sig", [pytest.param(signal.SIGINT, marks=pytest.mark.slow), signal.SIGKILL])
def test_an_interrupted_run_leaves_no_orphans_and_resumes_to_the_same_bytes(package, tmp_path, sig):
    """A real `darthand render-dataset` with two workers, interrupted once frames exist: the workers are gone within
    seconds, no temporary files stay after the resumed run, and its frames equal an uninterrupted run's bytes."""
    args = ["render-dataset", *_cli(package, "--count", "16", "--seed", "9", "--processes", "2", "--shard-size",
                                    "8")]
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    out = tmp_path / "cut"
    proc = subprocess.Popen([sys.executable, "-m", "darthand.cli", *args, "--out", str(out)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list((out / "labels").glob("0*.json"))) < 3:
        time.sleep(0.05)
    workers = _children(proc.pid)
    assert len(workers) >= 2 and proc.poll() is None
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    if sig == signal.SIGINT:
        assert proc.returncode == 130 and err.strip().splitlines()[-1] == "darthand: interrupted", err
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(_alive(w) for w in workers):
        time.sleep(0.1)
    assert not [w for w in workers if _alive(w)], "worker processes outlived their parent"
    resume = [a if a != "2" else "1" for a in args]                     # the resume, in this process
    assert main([*resume, "--out", str(out)]) == 0
    whole = tmp_path / "whole"
    assert main([*resume, "--out", str(whole)]) == 0
    assert files_of(out) == files_of(whole)
    assert not [p for p in out.rglob(".*") if p.is_file()]


def test_chunks_group_frames_by_texture_across_sides():
    items = [({"index": i, "side": "lr"[i % 3 == 0], "texture": "ab"[i % 2], "accessory": "none"}, str(i))
             for i in range(40)]
    chunks = run.make_chunks(items, processes=2, chunk_size=4)
    assert sorted(j["index"] for c in chunks for j, _ in c) == list(range(40))
    assert all(len({j["texture"] for j, _ in c}) == 1 and len(c) <= 4 for c in chunks)
    assert len(chunks) == 10                       # 20 frames per texture, both sides together: 5 chunks of 4 each
    assert [len(c) for c in chunks] == sorted((len(c) for c in chunks), reverse=True)


def test_chunks_group_frames_by_map_when_the_maps_outnumber_a_workers_cache():
    """Over more maps than a worker keeps prepared (MAPS_KEPT), a chunk holds one map (a map costs about two frames
    to prepare); over fewer, chunks stay grouped by texture, and a two-hand job counts its first hand's texture."""
    from darthand.render.environment import MAPS_KEPT

    def jobs(maps: int) -> list:
        return [({"index": i, "side": "r", "texture": f"t{i % 5}", "accessory": "none",
                  "lights": {"environment": {"map": f"m{i % maps}.exr", "strength": 1.0}}}, str(i)) for i in range(120)]

    many = run.make_chunks(jobs(MAPS_KEPT + 4), processes=2, chunk_size=8)
    assert sorted(j["index"] for c in many for j, _ in c) == list(range(120))
    assert all(len({run.job_map(j) for j, _ in c}) == 1 for c in many)
    assert all([run.job_texture(j) for j, _ in c] == sorted(run.job_texture(j) for j, _ in c) for c in many)
    few = run.make_chunks(jobs(MAPS_KEPT), processes=2, chunk_size=8)
    assert all(len({j["texture"] for j, _ in c}) == 1 for c in few)
    assert any(len({run.job_map(j) for j, _ in c}) > 1 for c in few)
    pair = {"index": 0, "bodies": [{"texture": "a"}, {"texture": "b"}]}
    assert run.job_texture(pair) == "a" and run.job_map(pair) == ""


def test_usd_packages_plan_their_gestures_by_name():
    from darthand.dataset.plan import Planner

    Package = BakedPackage
    assert isinstance(Package(), FrameSource)
    planner = Planner({"sides": ["right"]}, {"right": Package()})
    jobs = list(planner.jobs(0, 20))
    assert {j["pose"] for j in jobs} == {"flat", "fist"} and {j["gesture"] for j in jobs} == {"flat", "fist"}
    with pytest.raises(InputError, match="baked gestures"):
        Planner({"poses": {"mode": "dart"}}, {"right": Package()})
    with pytest.raises(InputError, match="'point' is not a gesture of the package"):
        Planner({"poses": {"gestures": ["point"]}}, {"right": Package()})


def test_an_only_background_that_does_not_decode_is_one_line_for_render_and_render_dataset(tmp_path):
    """A truncated PNG as the only background: both commands refuse it with the same one line on stderr (libpng's
    own message, printed on file descriptor 2 by the decoder, kept out), exit 2, before anything renders."""
    from darthand.render.image import write_png

    write_png(tmp_path / "good.png", np.tile(np.arange(64, dtype=np.uint8)[None, :, None] * 4, (48, 1, 3)))
    data = (tmp_path / "good.png").read_bytes()
    (tmp_path / "bg").mkdir()
    (tmp_path / "bg" / "cut.png").write_bytes(data[:len(data) // 2])
    cut = str(tmp_path / "bg" / "cut.png")
    runs = {"render": ["render", "open", "--background", cut, "--size", "32", "--out", str(tmp_path / "r")],
            "file": ["render-dataset", "open", "--backgrounds", cut, "--count", "2", "--size", "32",
                     "--processes", "1", "--out", str(tmp_path / "d1")],
            "folder": ["render-dataset", "open", "--backgrounds", str(tmp_path / "bg"), "--count", "2", "--size",
                       "32", "--processes", "1", "--out", str(tmp_path / "d2")]}
    for name, argv in runs.items():
        done = subprocess.run([sys.executable, "-m", "darthand.cli", *argv], capture_output=True, text=True,
                              timeout=300)
        assert done.returncode == 2, (name, done.stderr)
        assert done.stderr.count("\n") == 1 and "libpng" not in done.stderr, (name, done.stderr)
        assert done.stderr.startswith(f"darthand: error: {cut}: cannot read background image: "), (name, done.stderr)
    assert not list((tmp_path / "d1").glob("images/*")) if (tmp_path / "d1").exists() else True
