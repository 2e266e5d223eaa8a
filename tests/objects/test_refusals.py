"""Bad input refused at catalogue build with one line naming it: a licence outside the allow-list, a mesh that is
not closed, holds NaN or has an absurd size; a refused item is listed in `skipped` and the build goes on; a spec
with no usable item is one line and exit 2; an open mesh the item lets the build repair is closed and recorded."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from darthand.errors import InputError
from darthand.objects import catalog as cat
from darthand.objects.build import build_objects
from darthand.objects.loader import load_object_catalog

REPO = Path(__file__).resolve().parents[2]


def write_obj(path: Path, vertices, faces) -> None:
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(vertices, float).tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in np.asarray(faces).tolist()]
    path.write_text("\n".join(lines) + "\n")


def spec_with(items: list[dict]) -> dict:
    spec = {"format": "darthand-object-catalog-spec", "format_version": 1, "seed": 1, "items": items}
    cat.check_spec(spec)
    return spec


def mesh_item(id_: str, mesh: str, **kw) -> dict:
    return {"id": id_, "category": "box", "kind": "mesh", "name": id_, "mesh": mesh, "source": "test",
            "licence": "CC0-1.0", **kw}


@pytest.fixture
def meshes(tmp_path) -> Path:
    box = trimesh.creation.box((0.05, 0.04, 0.03))
    write_obj(tmp_path / "good.obj", box.vertices, box.faces)
    write_obj(tmp_path / "open.obj", box.vertices, box.faces[1:])                # one triangle missing
    nan = np.array(box.vertices)
    nan[2, 1] = np.nan
    write_obj(tmp_path / "nan.obj", nan, box.faces)
    write_obj(tmp_path / "huge.obj", box.vertices * 40, box.faces)               # 2 m across
    write_obj(tmp_path / "tiny.obj", box.vertices * 0.05, box.faces)             # 2.5 mm across
    return tmp_path


@pytest.mark.parametrize("name, kw, why", [
    ("open.obj", {}, "not closed"),
    ("nan.obj", {}, "NaN"),
    ("huge.obj", {}, "absurd size"),
    ("tiny.obj", {}, "absurd size"),
    ("good.obj", {"licence": "CC-BY-NC-4.0"}, "licence 'CC-BY-NC-4.0' is not one of"),
    ("good.obj", {"licence": "proprietary"}, "licence 'proprietary'"),
])
def test_a_bad_item_is_skipped_with_why_and_the_build_goes_on(meshes, tmp_path, name, kw, why):
    spec = spec_with([mesh_item("bad", name, **kw), mesh_item("good", "good.obj")])
    data = build_objects(spec, tmp_path / "out", meshes, sheet=False)
    assert [o["id"] for o in data["objects"]] == ["good"]
    (skip,) = data["skipped"]
    assert skip["id"] == "bad" and why in skip["why"] and "\n" not in skip["why"]
    assert not (tmp_path / "out" / "bad.npz").exists()


def test_a_procedural_item_with_a_forbidden_licence_is_refused(tmp_path):
    spec = spec_with([{"id": "ball", "category": "ball", "kind": "ball", "name": "ball", "diameter_mm": 60,
                       "color": [[0.5, 0.5, 0.5]], "roughness": 0.5, "licence": "GPL-3.0"},
                      {"id": "ok", "category": "ball", "kind": "ball", "name": "ok", "diameter_mm": 60,
                       "color": [[0.5, 0.5, 0.5]], "roughness": 0.5}])
    data = build_objects(spec, tmp_path, tmp_path, sheet=False)
    assert data["skipped"][0]["id"] == "ball" and "GPL-3.0" in data["skipped"][0]["why"]
    assert data["objects"][0]["licence"] == "CC0-1.0"


def test_an_open_mesh_the_item_lets_be_repaired_is_closed_and_recorded(meshes, tmp_path):
    data = build_objects(spec_with([mesh_item("fixed", "open.obj", repair=True)]), tmp_path / "out", meshes,
                         sheet=False)
    (entry,) = data["objects"]
    assert any("filled holes" in r for r in entry["repairs"])
    (item,) = load_object_catalog(tmp_path / "out")
    mesh = trimesh.Trimesh(item.vertices, item.faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume == pytest.approx(0.05 * 0.04 * 0.03)


def test_no_usable_item_is_one_error(meshes, tmp_path):
    spec = spec_with([mesh_item("bad", "open.obj")])
    with pytest.raises(InputError, match="no usable object .first: bad: .*not closed"):
        build_objects(spec, tmp_path / "out", meshes, sheet=False)


def test_the_command_says_it_in_one_line_and_exits_2(meshes, tmp_path):
    spec = spec_with([mesh_item("bad", "nan.obj")])
    path = meshes / "spec.json"
    path.write_text(json.dumps(spec))
    env = {"PYTHONPATH": f"{REPO / 'tools'}:{REPO}", "PATH": "/usr/bin:/bin"}
    run = subprocess.run([sys.executable, "-m", "darthand.cli", "objects", "build", "--spec", str(path), "--out",
                          str(tmp_path / "out")], capture_output=True, text=True, env=env, timeout=120)
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "no usable object" in lines[0] and "NaN" in lines[0], run.stderr


def test_spec_errors_name_the_field():
    spec = json.loads(cat.DEFAULT_SPEC.read_text())
    spec["items"][2]["category"] = "spoon"
    with pytest.raises(InputError, match="items.2"):
        cat.check_spec(spec, "catalog.json")
    spec = json.loads(cat.DEFAULT_SPEC.read_text())
    spec["items"][3]["id"] = spec["items"][0]["id"]
    with pytest.raises(InputError, match="repeats id"):
        cat.check_spec(spec, "catalog.json")


def test_an_items_draws_depend_only_on_seed_and_id():
    spec = cat.load_spec()
    item = next(i for i in spec["items"] if i["id"] == "mug_03")
    a = cat.resolve(spec, item)
    shuffled = {**spec, "items": list(reversed(spec["items"]))}
    assert cat.resolve(shuffled, item) == a
    assert cat.resolve({**spec, "seed": spec["seed"] + 1}, item) != a
    assert 0.078 <= a["diameter"] <= 0.084 and a["color"] in spec["defaults"]["mug"]["color"]
