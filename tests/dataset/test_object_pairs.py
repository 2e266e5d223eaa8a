"""Two hands on one object (interaction types held and handover, dataset/object_pairs.py): asked for by name only
(the default mix and every plan without them unchanged), planned from a small catalogue (trimesh's sphere and box,
grasps fitted on the test model's two sides) and checked by independent measures: winding numbers and trimesh's
closest points (no hand into the object deeper than 1 mm), MeshLab's intersection test on the two hands' meshes,
the sphere's closed form (contacts on its surface), the object's pixels against the object alone rasterised from
its mesh, keypoints behind the object (a ray-triangle test) hidden, each hand's mesh posed back by its side's
model, and a planned jobs file rendering the same."""

from __future__ import annotations

import io
import json
import sys
from pathlib import Path

import numpy as np
import pymeshlab
import pytest
import trimesh

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "render"))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "grasps"))
from object_catalog import SPHERE_RADIUS, toy_items, write_catalog  # noqa: E402
from truth import winding_numbers  # noqa: E402

from darthand.cli import main  # noqa: E402
from darthand.dataset import object_pairs  # noqa: E402
from darthand.dataset.interaction_shares import TYPES, parse_shares  # noqa: E402
from darthand.dataset.jobs import check_jobs, validate_jobs, write_jobs  # noqa: E402
from darthand.dataset.options import DatasetOptions  # noqa: E402
from darthand.dataset.plan import Planner, plan_spec  # noqa: E402
from darthand.dataset.run import render_frames  # noqa: E402
from darthand.errors import InputError  # noqa: E402
from darthand.fileio import read_json  # noqa: E402
from darthand.model.forward import forward  # noqa: E402
from darthand.model.mirror import mirror_model  # noqa: E402
from darthand.model.npz_io import save_npz  # noqa: E402
from darthand.render.image import read_png  # noqa: E402
from darthand.render.objects import ObjectLibrary  # noqa: E402
from darthand.render.scenes import Scene  # noqa: E402

FRAMES = 8
SIZE = 64
PASS_MM = 1.0


def test_object_types_are_asked_for_by_name_only():
    assert parse_shares(None) == {t: 1.0 / len(TYPES) for t in TYPES}      # the default mix: issue 29's seven
    assert "held" not in plan_spec(two_hands=0.5)["interactions"]
    shares = parse_shares("held=0.5,handover=0.5")
    assert shares["held"] == shares["handover"] == 0.5 and all(shares[t] == 0 for t in TYPES)
    with pytest.raises(InputError, match=r"^interactions: 'carried' is not an interaction type \(apart, .*, held, "
                                         r"handover\)$"):
        parse_shares("carried=1")


def test_object_types_without_catalogues_are_refused_in_one_line(sources):
    opened, _ = sources
    with pytest.raises(InputError, match=r"^interactions held/handover: the plan needs the object and grasp "
                                         r"catalogues \(--objects-catalog, --grasps-catalog\)$"):
        Planner({"two_hands": 1.0, "interactions": {"held": 1.0}}, opened)


def test_forearms_apart_by_the_exact_distance_of_two_skew_segments():
    """Perpendicular segments at heights 0 and d whose nearest points (x = y = 0) lie a quarter along each: their
    distance is d exactly; 30 um under the clearance is too close (a 64-point sampling would find ~0.06 mm more)."""
    clear = object_pairs.FOREARM_CLEAR_M

    def arm(axis, height):
        start, end = np.zeros(3), np.zeros(3)
        start[axis], end[axis], start[2], end[2] = -0.1, 0.3, height, height
        return object_pairs.TableHand(None, None, (start, end))

    assert not object_pairs.forearms_apart(arm(0, 0.0), arm(1, clear - 3e-5))
    assert object_pairs.forearms_apart(arm(0, 0.0), arm(1, clear + 3e-5))


@pytest.fixture(scope="module")
def catalogues(hand, tmp_path_factory):
    """(objects catalogue, grasp catalogue): the toy ball's and box's grasps fitted on both sides of the test
    model."""
    from darthand.grasps.build import build_grasps

    root = tmp_path_factory.mktemp("object_pairs")
    items = [i for i in toy_items() if i.id in ("ball_01", "box_01")]
    catalog = write_catalog(root / "objects", items)
    models = {"right": root / "right.npz", "left": root / "left.npz"}
    save_npz(hand, models["right"])
    save_npz(mirror_model(hand), models["left"])
    build_grasps(items, {s: str(p) for s, p in models.items()}, root / "grasps", sheet=False)
    return str(catalog), str(root / "grasps")


@pytest.fixture(scope="module")
def planned(sources, catalogues):
    """(planner spec, jobs): FRAMES frames, held and handover in equal shares."""
    opened, _ = sources
    spec = {"seed": 5, "two_hands": 1.0, "interactions": {"held": 0.5, "handover": 0.5}}
    planner = Planner(spec, opened, {"objects": catalogues[0], "grasps": catalogues[1]})
    return spec, list(planner.jobs(0, FRAMES))


@pytest.mark.slow
def test_planned_frames_hold_one_object_in_both_hands(sources, catalogues, planned):
    opened, _ = sources
    spec, jobs = planned
    kinds = {job["interaction"]["type"] for job in jobs}
    assert kinds <= {"held", "handover", "apart"} and kinds & {"held", "handover"}
    library = ObjectLibrary.load(catalogues[0])
    for job in jobs:
        assert Scene.from_job(job).to_job() == job
        if job["interaction"]["type"] == "apart":
            assert job["interaction"]["redrawn_from"] in ("held", "handover")
            continue
        right, left, held = job["bodies"]
        assert (right["side"], left["side"], held["kind"]) == ("right", "left", "object")
        assert [g["side"] for g in job["grasps"]] == ["right", "left"]
        assert all(g["id"].startswith(held["object"] + "/") for g in job["grasps"])
        roles = sorted(g["role"] for g in job["grasps"])
        assert roles == (["held", "held"] if job["interaction"]["type"] == "held" else ["giver", "receiver"])
        item = library.item(held["object"])
        hands = [posed_mesh(opened[b["side"]].pose_model(), b) for b in (right, left)]
        obj = trimesh.Trimesh(item.vertices, item.faces).apply_transform(np.asarray(held["placement"]))
        for mesh in hands:
            assert depth_inside(obj, mesh.vertices) <= PASS_MM * 1e-3
        assert meshlab_crossing_faces(*hands) == 0
    validate_jobs(opened, check_jobs(jobs), objects=library)
    again = Planner(spec, opened, {"objects": catalogues[0], "grasps": catalogues[1]})
    assert [again.job(j["index"]) for j in jobs[::-1]] == jobs[::-1]       # frame i depends on (seed, i) only


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["held", "handover"])
def test_both_hands_on_a_sphere_by_its_closed_form(hand, catalogues, tmp_path, kind):
    ball = [i for i in toy_items() if i.id == "ball_01"]
    pairs = object_pairs.ObjectPairs(write_catalog(tmp_path / "ball", ball), catalogues[1], hand, mirror_model(hand))
    drawn = 0
    for index in range(4):
        draw, _ = pairs.sample(kind, 1, index, None)
        if draw is None:
            continue
        drawn += 1
        P = np.linalg.inv(draw.object_placement)         # world -> the sphere's frame (centre at the origin)
        for side, pose, T in (("right", draw.right_pose, np.eye(4)), ("left", draw.left_pose, draw.placement)):
            model = hand if side == "right" else mirror_model(hand)
            v = forward(model, pose).vertices[0] @ T[:3, :3].T + T[:3, 3]
            r = np.linalg.norm(v @ P[:3, :3].T + P[:3, 3], axis=1)
            assert r.min() >= SPHERE_RADIUS - PASS_MM * 1e-3 - 5e-5           # none deeper than 1 mm (the sag)
            receiver = kind == "handover" and side == draw.receiver
            gap = r.min() - SPHERE_RADIUS
            assert (0.005 < gap < 0.06) if receiver else (gap < 0.002)         # on it, or a few cm short
    assert drawn >= 2


def test_missing_catalogues_are_refused_in_one_line(sources, tmp_path, capsys):
    package = sources[1]["right"].package
    args = ["render-dataset", str(package), "--out", str(tmp_path / "out"), "--count", "2", "--two-hands", "1",
            "--interactions", "held=0.5,handover=0.5"]
    assert main(args + ["--objects-catalog", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"darthand: error: {tmp_path / 'none'}: no object catalogue there (build it: " \
                  "`make build/objects/catalog.json`)"


@pytest.mark.slow
def test_a_ring_is_left_off_the_hand_on_the_object(sources, catalogues):
    """Every frame drawn with the test build's ring: on held and handover frames nobody wears it (as on a one-hand
    object frame: dataset/objects.LEFT_OFF) and the interaction's object record says it was left off."""
    opened, _ = sources
    spec = {"seed": 5, "two_hands": 1.0, "interactions": {"held": 1.0}, "accessory_share": 1.0}
    jobs = list(Planner(spec, opened, {"objects": catalogues[0], "grasps": catalogues[1]}).jobs(0, 4))
    on_object = [j for j in jobs if j["interaction"]["type"] == "held"]
    assert on_object
    for job in on_object:
        assert [b.get("accessory") for b in job["bodies"][:2]] == ["none", "none"]
        assert job["sample"]["accessory"] == "none" and job["interaction"]["object"]["accessory_left_off"] == "ring"
    validate_jobs(opened, check_jobs(jobs), objects=ObjectLibrary.load(catalogues[0]))


@pytest.mark.slow
def test_object_categories_restrict_the_objects_of_both_hands(sources, catalogues):
    spec = {"seed": 2, "two_hands": 1.0, "interactions": {"held": 1.0}, "object_categories": ["box"]}
    assert plan_spec(**spec)["object_categories"] == ["box"]
    assert "object_categories" not in plan_spec(two_hands=1.0, object_categories=["box"])   # as before: no objects
    planner = Planner(spec, sources[0], {"objects": catalogues[0], "grasps": catalogues[1]})
    jobs = [planner.job(i) for i in range(3)]
    assert {j["bodies"][2]["object"] for j in jobs if j["interaction"]["type"] == "held"} == {"box_01"}


@pytest.mark.slow
def test_a_frame_whose_draws_all_fail_falls_back_apart(sources, catalogues, monkeypatch):
    monkeypatch.setattr(object_pairs.ObjectPairs, "draw", lambda self, kind, u, models: None)
    planner = Planner({"seed": 1, "two_hands": 1.0, "interactions": {"held": 1.0}}, sources[0],
                      {"objects": catalogues[0], "grasps": catalogues[1]})
    job = planner.job(0)
    assert job["interaction"]["type"] == "apart" and job["interaction"]["redrawn_from"] == "held"
    assert job["interaction"]["attempts"] == object_pairs.ATTEMPTS + 1
    assert [b["kind"] for b in job["bodies"]] == ["hand", "hand"] and "grasps" not in job


@pytest.mark.slow
def test_no_suitable_pair_is_refused_in_one_line(sources, catalogues, monkeypatch):
    monkeypatch.setattr(object_pairs, "MIN_EXTENT_M", 1.0)
    with pytest.raises(InputError, match=r"^held/handover: no object of the catalogue takes two hands"):
        Planner({"two_hands": 1.0, "interactions": {"handover": 1.0}}, sources[0],
                {"objects": catalogues[0], "grasps": catalogues[1]})


@pytest.mark.slow
def test_one_hand_object_frames_share_the_pairs_catalogues_where_the_sides_agree(sources, catalogues, monkeypatch):
    """A plan of one-hand object frames and held/handover frames builds the catalogues and distance fields once
    when both draw on the same models (both sides), and plans what two separate samplers plan; with one side asked
    the one-hand sampler is its own (it describes that side only)."""
    from darthand.dataset import plan

    catalogs = {"objects": catalogues[0], "grasps": catalogues[1]}
    spec = {"seed": 3, "objects": 0.4, "two_hands": 0.5, "interactions": {"held": 0.5, "handover": 0.5}}
    shared = Planner(spec, sources[0], catalogs)
    assert shared.object_frames is shared.pairs.objects.frames
    jobs = [shared.job(i) for i in range(FRAMES)]
    assert {j["interaction"]["type"] for j in jobs if "interaction" in j} & {"held", "handover"}
    assert any("grasp" in j for j in jobs)
    one_side = Planner({**spec, "sides": ["right"]}, sources[0], catalogs)
    assert one_side.object_frames is not one_side.pairs.objects.frames
    assert set(one_side.object_frames.grasps) == {"right"}
    monkeypatch.setattr(plan, "_same_models", lambda a, b: False)
    apart = Planner(spec, sources[0], catalogs)
    assert apart.object_frames is not apart.pairs.objects.frames
    assert [apart.job(i) for i in range(FRAMES)] == jobs
    assert apart.describe() == shared.describe()


@pytest.fixture(scope="module")
def rendered(sources, catalogues, planned, tmp_path_factory):
    """(dataset folder, jobs file): the planned frames rendered, and their jobs file."""
    opened, specs = sources
    root = tmp_path_factory.mktemp("pairs_dataset")
    jobs = planned[1][:4]
    write_jobs(root / "jobs.json", jobs)
    options = DatasetOptions(specs["right"].package, str(root / "dataset"), size=SIZE, samples=4, progress=False,
                             processes=1, objects_catalog=catalogues[0])
    render_frames(options, opened, specs, jobs=jobs)
    return root / "dataset", root / "jobs.json"


@pytest.mark.slow
def test_labels_of_two_hands_on_one_object(sources, catalogues, rendered):
    opened, _ = sources
    root, _ = rendered
    library = ObjectLibrary.load(catalogues[0])
    checked = 0
    for path in sorted((root / "labels").glob("*.json")):
        labels = read_json(path, "labels")
        if labels["interaction"]["type"] == "apart":
            continue
        n = path.stem
        (entry,) = labels["objects"]
        assert entry["instance"] == 5                               # 1 + 2 B + k, B = 2 hands
        assert [g["hand"] for g in entry["grasps"]] == [0, 1] and entry["grasp"]["id"] == entry["grasps"][0]["id"]
        assert [c["hand"] for c in entry["hand_contacts"]] == [0, 1]
        assert entry["contacts"] == {k: entry["hand_contacts"][0][k] for k in entry["contacts"]}
        meshes = np.load(root / "meshes" / f"{n}.npy")
        assert meshes.shape[0] == 2
        for b, hand in enumerate(labels["hands"]):                  # each hand's mesh posed back by its model
            model = opened[hand["side"]].pose_model()
            m = hand["mano"]
            posed = forward(model, np.concatenate([m["global_orient"], m["hand_pose"]]), np.asarray(m["betas"]),
                            trans=np.asarray(m["trans"])).vertices[0]
            assert np.abs(posed - meshes[b]).max() < 1e-4
        item = library.item(entry["id"])
        obj = trimesh.Trimesh(np.load(root / "object_meshes" / f"{n}.npy"), item.faces)   # camera frame
        if item.id == "ball_01":           # closed form: contacts on the sphere's surface
            centre = obj.vertices.mean(0)
            for c, mesh in zip(entry["hand_contacts"], meshes):
                points = np.asarray(c["object_points"]).reshape(-1, 3)
                assert np.all(np.abs(np.linalg.norm(points, axis=1) - SPHERE_RADIUS) < 2e-4)
                d = np.linalg.norm(mesh[c["hand_vertices"]] - centre, axis=1)
                assert np.all((d > SPHERE_RADIUS - 1.2e-3) & (d < SPHERE_RADIUS + 3.2e-3))
        check_object_pixels(root, n, labels, entry, obj)
        check_hidden_keypoints(labels, obj)
        checked += 1
    assert checked


@pytest.mark.slow
def test_a_planned_jobs_file_renders_the_same(sources, catalogues, rendered, tmp_path):
    opened, specs = sources
    root, jobs_file = rendered
    options = DatasetOptions(specs["right"].package, str(tmp_path / "again"), size=SIZE, samples=4, progress=False,
                             processes=1, objects_catalog=catalogues[0])
    render_frames(options, opened, specs, jobs=check_jobs(json.loads(jobs_file.read_text())))
    for path in sorted((root / "images").glob("*.png")):
        assert (tmp_path / "again" / "images" / path.name).read_bytes() == path.read_bytes()
        for kind in ("instances", "object_meshes"):
            for first in (root / kind).glob(path.stem + ".*"):
                assert (tmp_path / "again" / kind / first.name).read_bytes() == first.read_bytes()


@pytest.mark.slow
def test_writers_of_two_hands_on_one_object(rendered, tmp_path, capsys):
    import webdataset as wds

    root, _ = rendered
    frames = sorted(p.stem for p in (root / "labels").glob("*.json"))
    assert main(["dataset", "export", str(root), "--format", "interhand", "--out", str(tmp_path / "ih")]) == 0
    assert main(["dataset", "export", str(root), "--format", "webdataset", "--out", str(tmp_path / "wds")]) == 0
    samples = {s["__key__"]: s for s in wds.WebDataset(sorted(str(p) for p in (tmp_path / "wds").glob("*.tar")),
                                                        shardshuffle=False)}
    for key in frames:
        assert np.array_equal(np.load(io.BytesIO(samples[key]["object.npy"])),
                              np.load(root / "object_meshes" / f"{key}.npy"))
    capsys.readouterr()
    assert main(["dataset", "export", str(root), "--format", "ho3d", "--out", str(tmp_path / "ho3d")]) == 2
    assert "no frame of a hand holding an object to write" in capsys.readouterr().err    # two hands: left out


# ------------------------------------------------------------------------------------------------ helpers


def posed_mesh(model, body: dict) -> trimesh.Trimesh:
    """A job's hand posed by its side's model and placed, as a trimesh."""
    v = forward(model, np.asarray(body["pose"]), None if body.get("betas") is None else np.asarray(body["betas"])
                ).vertices[0]
    P = np.asarray(body.get("placement", np.eye(4)), np.float64)
    return trimesh.Trimesh(v @ P[:3, :3].T + P[:3, 3], model.faces, process=False)


def meshlab_crossing_faces(a: trimesh.Trimesh, b: trimesh.Trimesh) -> int:
    """Faces of either hand crossing a face of the other: MeshLab's self-intersection test on both meshes as one,
    less each one's own."""
    def crossing(vertices, faces):
        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.asarray(vertices, np.float64), face_matrix=np.asarray(faces)))
        ms.compute_selection_by_self_intersections_per_face()
        return ms.current_mesh().face_selection_array().astype(bool)

    both = crossing(np.concatenate([a.vertices, b.vertices]), np.concatenate([a.faces, b.faces + len(a.vertices)]))
    alone = np.concatenate([crossing(a.vertices, a.faces), crossing(b.vertices, b.faces)])
    return int((both & ~alone).sum())


def depth_inside(obj: trimesh.Trimesh, points: np.ndarray) -> float:
    """The deepest of `points` inside the closed mesh `obj` (m; 0 when none is): the winding number says inside,
    trimesh's exact closest point over every face how deep."""
    inside = points[winding_numbers(obj.vertices, obj.faces, points) > 0.5]
    if not len(inside):
        return 0.0
    _, distance, _ = trimesh.proximity.closest_point_naive(obj, inside)
    return float(distance.max())


def rasterise(labels: dict, obj: trimesh.Trimesh) -> np.ndarray:
    """(H, W) bool: pixel centres inside any of the camera-frame mesh's triangles projected by the labels' K."""
    w, h = labels["image_size"]
    uv = obj.vertices @ np.asarray(labels["K"]).T
    uv = uv[:, :2] / uv[:, 2:]
    rows, cols = np.mgrid[0:h, 0:w]
    p = np.stack([cols + 0.5, rows + 0.5], axis=-1).reshape(-1, 2)
    out = np.zeros(len(p), bool)
    for a, b, c in uv[obj.faces]:
        e = [(b - a, p - a), (c - b, p - b), (a - c, p - c)]
        s = np.stack([u[0] * v[:, 1] - u[1] * v[:, 0] for u, v in e])
        out |= (s >= 0).all(axis=0) | (s <= 0).all(axis=0)
    return out.reshape(h, w)


def check_object_pixels(root: Path, n: str, labels: dict, entry: dict, obj: trimesh.Trimesh) -> None:
    """The instance map's object pixels are pixels of the object rasterised alone (up to its silhouette's pixels),
    and their share of those is the labels' visible fraction."""
    alone = rasterise(labels, obj)
    seen = read_png(root / "instances" / f"{n}.png")[..., 0] == entry["instance"]
    grown = alone | np.pad(alone, 1)[2:, 1:-1] | np.pad(alone, 1)[:-2, 1:-1] | np.pad(alone, 1)[1:-1, 2:] \
        | np.pad(alone, 1)[1:-1, :-2]
    assert seen.sum() > 0 and not (seen & ~grown).any()
    assert abs(entry["visible_fraction"] - seen.sum() / alone.sum()) < 0.1


def ray_distances(directions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(K,) distance along each unit ray from the origin to its first triangle hit (Moller-Trumbore; inf: none)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    e1, e2 = b - a, c - a
    out = np.full(len(directions), np.inf)
    for k, d in enumerate(directions):
        p = np.cross(d, e2)
        det = (e1 * p).sum(1)
        ok = np.abs(det) > 1e-15
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = -a
        u = (s * p).sum(1) * inv
        q = np.cross(s, e1)
        v = (q * d).sum(1) * inv
        t = (e2 * q).sum(1) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        if hit.any():
            out[k] = t[hit].min()
    return out


def check_hidden_keypoints(labels: dict, obj: trimesh.Trimesh) -> None:
    """A keypoint whose ray from the camera meets the object more than 5 mm before it is not visible."""
    for hand in labels["hands"]:
        points = np.asarray(hand["keypoints_3d"])
        length = np.linalg.norm(points, axis=1)
        first = ray_distances(points / length[:, None], obj.vertices[obj.faces])
        behind = first < length - 5e-3
        assert not np.asarray(hand["visibility"])[behind].any()
