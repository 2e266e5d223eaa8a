"""`darthand render-dataset`: planning (determinism, frame independence, limits), rendering over processes (the
same bytes as in one process), resume, labels pointing at their files, one-line errors."""

from __future__ import annotations

import json

import numpy as np
import OpenImageIO as oiio
import pytest

from darthand.cli import main
from darthand.errors import InputError
from darthand.model.anatomy import axis_angle_to_angles, limits_radians
from darthand.model.npz_io import save_npz
from darthand.model.poses import gesture_angles, list_gestures
from darthand.render import dataset as ds
from darthand.render.api import open_source
from darthand.schemas import check_schema

SIZE = 48          # pixels: the frames only have to be real renders, not pretty ones
TEXTURES = ("light_test_00", "light_test_01")


# ------------------------------------------------------------------------------------------------ fixtures


@pytest.fixture(scope="module")
def package(hand, texture_files, ring, tmp_path_factory):
    """(model .npz, texture catalogue, accessory catalogue) on disk, as worker processes open them: the open hand
    with the wrist, two texture variants (the test skin, twice) and the ring."""
    root = tmp_path_factory.mktemp("package")
    model = root / "model" / "right.npz"
    save_npz(hand, model)
    tex = root / "textures"
    tex.mkdir()
    for name in ("skin.png", "rough.png"):
        (tex / name).write_bytes((texture_files.albedo.parent / name).read_bytes())
    sha = "0" * 64
    entry = {"category": "moles", "kind": "overlay", "tone": "light", "mst": 2.0, "tone_srgb": [0.8, 0.6, 0.5],
             "offset": 0.0, "seed": 1, "resolution": 256, "sha256": sha, "fingerprint": sha, "params": {"skin": {}},
             "files": {"albedo": "skin.png", "roughness": "rough.png", "tx": None}}
    write(tex / "catalog.json", {
        "format": "darthand-texture-catalog", "version": 1, "resolution": 256, "seed": 1, "spec_sha256": sha,
        "bake": {"key": sha, "uvs": "model", "labels": "labels.png", "coverage": "coverage.png"},
        "model": {"source": "test", "vertices": len(hand.v_template), "faces": len(hand.faces)},
        "contact_sheet": None, "entries": [dict(entry, id=t, index=i) for i, t in enumerate(TEXTURES)]})
    acc = root / "accessories"
    acc.mkdir()
    np.savez(acc / "ring_test.npz", vertices=ring.vertices, faces=ring.faces)
    write(acc / "catalog.json", {
        "format": "darthand-accessory-catalog", "format_version": 1, "seed": 1,
        "model": {"source": "test", "side": "right"},
        "accessories": [{"id": "ring_test", "type": "ring", "style": "torus", "parent_joint": ring.parent_joint,
                         "rest_transform": np.eye(4).tolist(), "fitted_size": {}, "vertices": len(ring.vertices),
                         "triangles": len(ring.faces), "max_penetration_mm": {"rest": 0.0, "poses": None},
                         "files": {"npz": "ring_test.npz", "obj": "-", "mtl": "-", "base_color": "-",
                                   "metallic_roughness": "-"},
                         "material": {**ring.material, "kind": "metal", "base_color_texture": None,
                                      "metallic_roughness_texture": None}}]})
    return str(model), str(tex), str(acc)


@pytest.fixture(scope="module")
def source(package):
    model, tex, acc = package
    return open_source(model, textures=tex, accessories=acc)


def write(path, doc) -> None:
    path.write_text(json.dumps(doc))


def render(package, out, jobs, **kw):
    model, tex, acc = package
    return ds.render_dataset(model, out, jobs, textures=tex, accessories=acc, size=SIZE, samples=4,
                             progress=False, **kw)


def files_of(folder) -> dict:
    """{relative path: bytes} of a dataset's frame files (dataset.json holds timings, so it differs)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != "dataset.json"}


def read_pixels(path) -> np.ndarray:
    buf = oiio.ImageBuf(str(path))
    assert not buf.has_error, buf.geterror()
    return buf.get_pixels(oiio.UINT8)


# ------------------------------------------------------------------------------------------------ planning


def test_same_seed_same_jobs_and_frame_depends_only_on_seed_and_index(source):
    jobs = ds.plan_frames(source, 12, seed=7)
    assert jobs == ds.plan_frames(source, 12, seed=7)
    assert [j["index"] for j in jobs] == list(range(12))
    # frames 4..9 of a longer plan are those of a plan starting at 4 (shards, resumes, extensions agree)
    assert ds.plan_frames(source, 6, seed=7, start=4) == jobs[4:10]
    assert ds.plan_frames(source, 30, seed=7)[:12] == jobs
    other = ds.plan_frames(source, 12, seed=8)
    assert sum(a["camera"] != b["camera"] for a, b in zip(jobs, other)) >= 10
    # one option does not shift another's draws: the same views whatever the textures
    narrowed = ds.plan_frames(source, 12, seed=7, textures=[TEXTURES[1]])
    assert [j["camera"] for j in narrowed] == [j["camera"] for j in jobs]
    assert {j["texture"] for j in narrowed} == {TEXTURES[1]}


def test_planned_jobs_follow_the_options_and_the_schema(source):
    jobs = ds.plan_frames(source, 200, seed=1, skin_tone_range=(-0.1, 0.1), skin_tone_steps=3,
                          no_accessory_share=0.3, roll_range_deg=(-20, 20), margin_range=(0.05, 0.1))
    check_schema({"frames": jobs}, ds.JOBS_SCHEMA, "plan")
    json.loads(json.dumps(jobs))                                         # plain JSON
    assert {j["texture"] for j in jobs} == set(TEXTURES)               # catalogue textures, never the checker
    assert {j["skin_tone_offset"] for j in jobs} == {-0.1, 0.0, 0.1}
    uniform = [j["skin_tone_offset"] for j in ds.plan_frames(source, 200, seed=1, skin_tone_range=(-0.2, 0.1))]
    assert min(uniform) >= -0.2 and max(uniform) <= 0.1 and len(set(uniform)) > 150
    assert np.mean(uniform) == pytest.approx(-0.05, abs=0.03)
    share = np.mean([j["accessory"] == "none" for j in jobs])
    assert 0.2 < share < 0.4 and {j["accessory"] for j in jobs} == {"none", "ring_test"}
    views = np.array([j["camera"]["view"] for j in jobs])
    assert np.allclose(np.linalg.norm(views, axis=1), 1, atol=1e-5)
    assert views[:, 0].max() <= ds.WRIST_CONE_COS and views[:, 0].min() < -0.8   # all round, not along the forearm
    assert all(-20 <= j["camera"]["roll_deg"] <= 20 and 0.05 <= j["camera"]["margin"] <= 0.1 for j in jobs)
    assert {j["gesture"] for j in jobs} == set(list_gestures())


def test_pose_jitter_stays_within_the_joint_limits(source):
    jobs = ds.plan_frames(source, 60, seed=3, pose_jitter_deg=10)
    angles = axis_angle_to_angles(source.model, np.array([j["pose"] for j in jobs]))
    base = np.stack([gesture_angles(j["gesture"]) for j in jobs])
    lim = limits_radians()
    tol = 1e-6
    assert ((angles >= np.minimum(lim[..., 0], base) - tol) & (angles <= np.maximum(lim[..., 1], base) + tol)).all()
    change = np.rad2deg(angles - base)[:, 1:]
    assert np.allclose(angles[:, 0], base[:, 0], atol=1e-9)             # the root is not perturbed
    free = (np.abs(change) < 5) & (np.abs(change) > 0)                  # not clipped: a Gaussian of std 10 deg
    assert 6 < np.sqrt(np.mean(change[np.abs(change) < 40] ** 2)) < 11 and free.mean() > 0.2
    still = ds.plan_frames(source, 5, seed=3, pose_jitter_deg=0)
    assert all(j["pose"] == j["gesture"] for j in still)               # no jitter: the gesture by name


def test_pose_files_join_the_gestures(source, tmp_path):
    poses = np.zeros((2, 48))
    poses[0, 5], poses[1, 3 * 4 + 2] = 0.4, -0.3
    (tmp_path / "poses.json").write_text(json.dumps({"pose": poses.tolist()}))
    jobs = ds.plan_frames(source, 40, seed=0, poses=["fist", str(tmp_path / "poses.json")], pose_jitter_deg=0)
    vectors = [j["pose"] for j in jobs if j["gesture"] is None]
    assert {j["pose"] for j in jobs if j["gesture"] is not None} == {"fist"}
    assert vectors and all(v in poses.tolist() for v in vectors) and len({tuple(v) for v in vectors}) == 2


def test_random_views_cover_the_zone_outside_the_forearm_cone():
    assert ds.random_view(0.0, 0.0) == [-1.0, 0.0, 0.0]
    top = ds.random_view(1.0, 0.25)
    assert top[0] == pytest.approx(ds.WRIST_CONE_COS) and top[2] == pytest.approx(0.6)
    # uniform on the zone: the mean of x over it is the midpoint of [-1, c] (Archimedes)
    u = np.random.default_rng(0).random((4000, 2))
    x = np.array([ds.random_view(a, b)[0] for a, b in u])
    assert np.mean(x) == pytest.approx((ds.WRIST_CONE_COS - 1) / 2, abs=0.03)


def test_usd_packages_plan_their_gestures_by_name():
    class Package:                           # what plan_frames asks of a USD package
        gestures = ["flat", "fist"]

        def texture_ids(self):
            return ["light_a_00"]

        def accessory_ids(self):
            return ["none", "watch_01"]

    jobs = ds.plan_frames(Package(), 20, seed=0)
    assert {j["pose"] for j in jobs} == {"flat", "fist"}
    with pytest.raises(InputError, match="baked gestures"):
        ds.plan_frames(Package(), 2, pose_jitter_deg=3)
    with pytest.raises(InputError, match="'point' is not a gesture of the package"):
        ds.plan_frames(Package(), 2, poses=["point"])


def test_chunks_group_frames_by_texture():
    jobs = [{"index": i, "texture": "ab"[i % 2], "skin_tone_offset": 0.1 * (i % 3 == 0), "accessory": "none"}
            for i in range(40)]
    chunks = ds.make_chunks(jobs, processes=2, chunk_size=4)
    assert sorted(j["index"] for c in chunks for j in c) == list(range(40))
    assert all(len({j["texture"] for j in c}) == 1 and len(c) <= 4 for c in chunks)
    assert [len(c) for c in chunks] == sorted((len(c) for c in chunks), reverse=True)


# ------------------------------------------------------------------------------------------------ rendering


def test_processes_2_write_the_same_bytes_as_processes_1(package, source, tmp_path):
    jobs = ds.plan_frames(source, 5, seed=2, no_accessory_share=0.4)
    assert {j["accessory"] for j in jobs} == {"none", "ring_test"}
    one = render(package, tmp_path / "one", jobs, processes=1, source=source)
    two = render(package, tmp_path / "two", jobs, processes=2, chunk_size=1)
    assert one["rendered"] == two["rendered"] == 5 and two["timings"]["processes"] == 2
    a, b = files_of(tmp_path / "one"), files_of(tmp_path / "two")
    assert len(a) == 15 and a == b
    drop_ms = [[{k: v for k, v in f.items() if k != "ms"} for f in doc["frames"]] for doc in (one, two)]
    assert drop_ms[0] == drop_ms[1] and [f["index"] for f in two["frames"]] == list(range(5))


def test_labels_point_at_their_image_and_mask(package, source, tmp_path):
    jobs = ds.plan_frames(source, 3, seed=4, start=998_999_999)          # a 9-digit index widens the names
    doc = render(package, tmp_path, jobs, processes=1, source=source)
    names = sorted(p.name for p in (tmp_path / "labels").iterdir())
    assert names == ["998999999.json", "999000000.json", "999000001.json"]
    for job, name in zip(jobs, names):
        labels = json.loads((tmp_path / "labels" / name).read_text())
        check_schema(labels, "labels.schema.json", name)
        image = read_pixels(tmp_path / "labels" / labels["files"]["image"])
        mask = read_pixels(tmp_path / "labels" / labels["files"]["mask"])
        assert labels["files"]["image"] == f"../images/{name[:-5]}.png"
        assert labels["render"]["dataset"]["frame"] == job["index"]
        assert labels["texture"]["id"] == job["texture"] and labels["accessory"]["id"] == job["accessory"]
        assert image.shape == (SIZE, SIZE, 4) and np.array_equal(image[..., 3], mask[..., 0])
        assert labels["coverage"] == pytest.approx(mask.mean() / 255, abs=0.01)
    assert [f["index"] for f in doc["frames"]] == [j["index"] for j in jobs]


def test_resume_skips_frames_already_rendered_from_the_same_job(package, source, tmp_path):
    jobs = ds.plan_frames(source, 3, seed=5)
    render(package, tmp_path, jobs, processes=1, source=source)
    labels = sorted((tmp_path / "labels").iterdir())
    stamps = [p.stat().st_mtime_ns for p in labels]
    again = render(package, tmp_path, jobs, processes=1, source=source)
    assert (again["rendered"], again["skipped"]) == (0, 3)
    assert [p.stat().st_mtime_ns for p in labels] == stamps
    assert [f["coverage"] for f in again["frames"]] == pytest.approx(
        [json.loads(p.read_text())["coverage"] for p in labels], abs=1e-5)
    (tmp_path / "masks" / "000001.png").unlink()                        # an interrupted frame
    changed = [dict(j) for j in jobs]
    changed[2]["texture"] = "plain"                                      # a changed job
    third = render(package, tmp_path, changed, processes=1, source=source)
    assert (third["rendered"], third["skipped"]) == (2, 1)
    assert json.loads(labels[2].read_text())["texture"]["id"] == "plain"
    forced = render(package, tmp_path, changed, processes=1, source=source, resume=False)
    assert forced["rendered"] == 3


def test_a_failing_frame_stops_the_run_with_its_index(package, source, tmp_path):
    bad = tmp_path / "pose.json"
    bad.write_text('{"pose": [' + ",".join(["0"] * 48) + "]}")
    jobs = [{"index": 0, "pose": "fist"}, {"index": 7, "pose": str(bad)}]
    check = ds.check_jobs(jobs)
    ds.validate_jobs(source, check)                                       # a readable file when checked ...
    bad.write_text("{not json")                                           # ... broken by the time it renders
    with pytest.raises(InputError, match=r"^frame 7: .*pose.json: not valid JSON"):
        render(package, tmp_path / "out", jobs, processes=1, source=source)


def test_a_failing_frame_in_a_worker_stops_the_run_with_its_index(package, source, tmp_path):
    bad = tmp_path / "pose.json"
    bad.write_text('{"pose": [' + ",".join(["0"] * 48) + "]}")
    jobs = [{"index": i, "pose": "fist"} for i in range(4)] + [{"index": 9, "pose": str(bad)}]
    model, tex, acc = package
    src = open_source(model, textures=tex, accessories=acc)
    ds.validate_jobs(src, ds.check_jobs(jobs))
    bad.write_text("{not json")
    with pytest.raises(InputError, match=r"^frame 9: "):
        render(package, tmp_path / "out", jobs, processes=2, chunk_size=1, source=src)


# ------------------------------------------------------------------------------------------------ command line


def test_cli_plans_renders_and_a_written_plan_renders_the_same(package, tmp_path, capsys):
    model, tex, acc = package
    common = [model, "--textures", tex, "--accessories", acc, "--size", str(SIZE), "--samples", "4",
              "--processes", "1", "--count", "3", "--seed", "11", "--gestures", "fist,point", "--views",
              "dorsal,random", "--skin-tone-range=-0.05,0.05"]
    assert main(["render-dataset", *common, "--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert "3 frames rendered" in out and "images/s" in out
    assert main(["render-dataset", *common, "--out", str(tmp_path / "unused"), "--plan",
                 str(tmp_path / "jobs.json")]) == 0
    assert not (tmp_path / "unused").exists()
    assert main(["render-dataset", model, "--textures", tex, "--accessories", acc, "--size", str(SIZE),
                 "--samples", "4", "--processes", "1", "--jobs", str(tmp_path / "jobs.json"),
                 "--out", str(tmp_path / "b")]) == 0
    assert files_of(tmp_path / "a") == files_of(tmp_path / "b")
    doc = json.loads((tmp_path / "a" / "dataset.json").read_text())
    assert doc["jobs"]["seed"] == 11 and doc["count"] == 3 and doc["rendered"] == 3
    assert {f["gesture"] for f in doc["frames"]} <= {"fist", "point"}


@pytest.mark.parametrize("case, expected", [
    ("not json", "not valid JSON"),
    ('{"frames": [{"pose": [1, 2]}]}', "field 'frames.0.pose'"),
    ('[{"texture": "light_nope_00"}]', "frame 0: texture 'light_nope_00' is not in"),
    ('[{"index": 3, "accessory": "watch_99"}]', "frame 3: accessory 'watch_99'"),
    ('[{"camera": {"view": "sideways"}}]', "frame 0: camera: field 'view'"),
    ('[{"index": 1}, {"index": 1}]', "repeats the index of job 0"),
])
def test_bad_jobs_file_is_a_one_line_error(package, tmp_path, capsys, case, expected):
    model, tex, acc = package
    (tmp_path / "jobs.json").write_text(case)
    rc = main(["render-dataset", model, "--textures", tex, "--accessories", acc, "--jobs",
               str(tmp_path / "jobs.json"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and err.startswith("darthand: error: ") and expected in err, err
    assert not (tmp_path / "out" / "images").exists()


@pytest.mark.parametrize("args, expected", [
    (["--texture-ids", "light_test_00,light_nope_00"], "textures: 'light_nope_00' is not one of"),
    (["--accessory-ids", "watch_99"], "accessories: 'watch_99'"),
    (["--gestures", "wave"], "poses: 'wave' is neither a gesture"),
    (["--views", "top"], "views: 'top'"),
    (["--skin-tone-range", "0.1"], "--skin-tone-range"),
    (["--count", "-1"], "count"),
])
def test_bad_planning_options_are_one_line_errors(package, tmp_path, capsys, args, expected):
    model, tex, acc = package
    rc = main(["render-dataset", model, "--textures", tex, "--accessories", acc, "--out", str(tmp_path), *args])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and expected in err, err
