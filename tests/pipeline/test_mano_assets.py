"""`make assets MANO=<a MANO-format pickle>` end to end, the way a user with a licensed MANO_RIGHT.pkl runs it.

The pickle is tests/model/mano_fixture's realistic MANO-format model (778 vertices, 1538 faces, 16-vertex wrist
loop, protocol 2, chumpy-style shapedirs, CSC regressor, no UVs, no face labels). The build runs in a copy of the
tree (Makefile, pyproject, tools, assets_src, schemas; .venv, .venv-blender and node_modules linked, PYTHONPATH on the
copy's tools), so the developer's own build/ is never touched, at RES=64.

Besides the finished build -- manifest, gesture report, validation of every package -- it checks the two failure
rules of `make assets`: a step that fails leaves nothing make takes as up to date, so it fails again on the next
run until its cause is fixed; and `make assets` exits non-zero while a check recorded in the manifest fails.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from darthand.model.gestures import angles_to_joints, joints_to_angles
from darthand.model.npz_io import load_npz, save_npz

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "model"))
from mano_fixture import write_mano_like  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
COPIED = ("Makefile", "pyproject.toml", "package.json", "package-lock.json", "tools", "assets_src", "schemas")
LINKED = (".venv", ".venv-blender", "node_modules")
# The copy's set-up inputs and the stamps of the linked folders they would refresh: the copy's inputs are dated
# before the stamps, so make in the copy never reinstalls the developer's .venv (from the copy, which goes away).
STAMPED = {"pyproject.toml": ".venv/.installed-stamp", "package.json": "node_modules/.installed-stamp",
           "package-lock.json": "node_modules/.installed-stamp", "Makefile": ".venv-blender/.installed-stamp"}
RES = 64
GRASP_OBJECTS = "mug_01 tennis_ball_01"    # the grasps stage on two objects (all 58: about 4 CPU minutes)
# The pose-library step on three poses, one that needs a fit on this hand (all 165: 4 CPU minutes; their fit is
# tested in tests/model/test_library_fit.py, this test checks the step runs in the pipeline and is recorded).
LIBRARY_POSES = "asl_b grip_tip_pinch_small rest_half_open_4"

pytestmark = pytest.mark.skipif(shutil.which("make") is None or not (REPO / ".venv" / "bin" / "darthand").exists(),
                                reason="needs GNU make and the project's .venv (made by `make test`)")


def copy_tree(dst: Path) -> Path:
    """A copy of the repository's build inputs at dst, sharing the repository's .venv and node_modules."""
    dst.mkdir(parents=True)
    for name in COPIED:
        src = REPO / name
        if src.is_dir():
            shutil.copytree(src, dst / name, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        elif src.exists():
            shutil.copy2(src, dst / name)
    for name in LINKED:
        if (REPO / name).exists():
            (dst / name).symlink_to(REPO / name)
    for name, stamp in STAMPED.items():
        if (REPO / stamp).exists() and (dst / name).exists():
            t = (REPO / stamp).stat().st_mtime - 1
            os.utime(dst / name, (t, t))
    return dst


def tree_env(tree: Path) -> dict:
    """The environment of a command run in the copy: its own tools first, no make variables of a calling make."""
    env = dict(os.environ, PYTHONPATH=str(tree / "tools"))
    for key in ("MAKEFLAGS", "MFLAGS", "MAKELEVEL"):
        env.pop(key, None)
    return env


def make(tree: Path, *targets: str, **variables) -> subprocess.CompletedProcess:
    env = tree_env(tree)
    args = ["make", "--no-print-directory", *targets, *(f"{k}={v}" for k, v in variables.items())]
    return subprocess.run(args, cwd=tree, env=env, capture_output=True, text=True, timeout=3600)


def record_manifest(tree: Path) -> None:
    """Write the copy's build/manifest.json again from what its build/ holds now."""
    subprocess.run([str(tree / ".venv" / "bin" / "darthand"), "manifest", "--build", "build"], cwd=tree,
                   env=tree_env(tree), check=True, capture_output=True, timeout=600)


@pytest.fixture(scope="module")
def tree():
    # Not pytest's tmp_path: its numbered folders are pruned by other pytest sessions on a shared machine, and
    # this build runs for minutes.
    with tempfile.TemporaryDirectory(prefix="darthand-mano-assets-") as root:
        right, _ = write_mano_like(Path(root) / "mano")
        yield copy_tree(Path(root) / "tree"), right


def crossing_gesture(model_path: Path, name: str = "ok") -> None:
    """Rewrite the model file with gesture `name` recorded as a pose in which the thumb passes through the index
    (as a fit that went wrong would leave it): the gesture guard must fail on it."""
    model = load_npz(model_path)
    record = json.loads(json.dumps(model.meta["gestures"]))
    angles = joints_to_angles(record["gestures"][name]["joints"])
    angles[15, 2] += np.deg2rad(40)       # thumb3 bend: the thumb tip sinks into the index finger
    angles[14, 2] += np.deg2rad(25)
    record["gestures"][name]["joints"] = angles_to_joints(angles)
    save_npz(model.replace(meta=dict(model.meta, gestures=record)), model_path)


def test_a_failed_step_from_a_mano_pickle_fails_every_time(tree):
    """The model and gesture steps from the MANO-format pickle; then a failed step fails every time until fixed:
    the gesture guard writes its report, then exits 1; make deletes both outputs of the step, so the next run
    checks again instead of building on."""
    tree, pkl = tree
    build = tree / "build"
    run = make(tree, "build/template/gestures.json", MANO=pkl, RES=RES)
    assert run.returncode == 0, run.stdout + run.stderr
    assert json.loads((build / "template" / "gestures.json").read_text())["fitted"] is True
    good = (build / "model" / "right.npz").read_bytes()

    # JOBS=1: make stops at the failed step. With two job slots it fails as soon, but waits for the step started
    # beside it (the pose library's fit, minutes) to finish before it exits: that step's output is valid and kept.
    crossing_gesture(build / "model" / "right.npz")
    for _ in range(2):
        run = make(tree, "assets", MANO=pkl, RES=RES, GRASP_OBJECTS=GRASP_OBJECTS, LIBRARY_POSES=LIBRARY_POSES,
                   JOBS=1)
        assert run.returncode != 0
        assert "gesture 'ok': " in run.stdout and "faces where digits intersect (thumb-index" in run.stdout
        assert not (build / "template" / "gestures.json").exists()
        assert not (build / "template" / "gestures.png").exists()
        assert not (build / "manifest.json").exists()
    (build / "model" / "right.npz").write_bytes(good)


# The whole build: about 2.5 CPU minutes (the 50 accessories fitted to the hand alone take about 1.5), the largest
# test of `make test`, kept there because it is the only run of the whole pipeline from a MANO-format source.
def test_make_assets_from_a_mano_pickle(tree):
    """`make assets MANO=<pickle>` to the end: manifest, fitted gestures on both sides, every package validated
    clean, render checks; and `make assets` failing on every run while a check in the manifest fails."""
    tree, pkl = tree
    build = tree / "build"
    run = make(tree, "assets", MANO=pkl, RES=RES, GRASP_OBJECTS=GRASP_OBJECTS, LIBRARY_POSES=LIBRARY_POSES)
    assert run.returncode == 0, run.stdout + run.stderr
    manifest = json.loads((build / "manifest.json").read_text())
    schema = json.loads((REPO / "schemas" / "manifest.schema.json").read_text())
    jsonschema.validate(manifest, schema)
    assert manifest["model"]["source"] == str(pkl)
    assert (manifest["model"]["vertices"], manifest["model"]["faces"]) == (842, 1666)
    assert manifest["failed_checks"] == []
    steps = set(manifest["steps_seconds"])
    assert {"model", "gestures", "textures", "accessories", "checks", "validate", "objects", "grasps",
            "pose-library"} <= steps
    fit = json.loads((build / "poses" / "right.json").read_text())
    assert sorted(fit["poses"]) == sorted(LIBRARY_POSES.split())
    kinds = ("usd", "gltf", "gltf-variants", "blend")
    assert {f"{kind}-{side}" for kind in kinds for side in ("right", "left")} <= steps

    # The gestures: fitted to this model, no digit through another on either side, the contacts touching.
    report = manifest["checks"]["gestures"]
    assert report["fitted"] is True
    for name, g in report["gestures"].items():
        assert g["between_fingers_faces"] == 0 and g["inverted_faces"] == 0, name
        assert g["mirror"]["between_fingers_faces"] == 0 and g["mirror"]["side"] == "left", name
        assert g["fit"]["status"] in ("kept", "fitted"), name
        for pair, mm in g["contacts"].items():
            assert 0.0 <= mm <= 1.0, (name, pair, mm)
    assert report["gestures"]["ok"]["contacts"] and report["gestures"]["pinch"]["contacts"]

    # Every package validated clean, every render check passed, the textures at RES, all accessories fitted.
    validate = manifest["checks"]["validate"]
    assert validate["exit_code"] == 0 and len(validate["packages"]) == 6
    assert all(p["status"] == "clean" for p in validate["packages"]), validate["packages"]
    assert manifest["checks"]["render"]["ok"] is True
    assert manifest["checks"]["textures"]["resolution"] == RES
    assert len(manifest["checks"]["accessories"]) == 50
    model = load_npz(build / "model" / "left.npz")
    assert model.side == "left" and model.face_labels is not None and model.has_uvs
    assert "uv_atlas" in model.meta and model.meta["gestures"]["gestures"].keys() == report["gestures"].keys()

    # A check the manifest records as failed fails `make assets`, on every run, until it passes again. The failing
    # report is recorded in the manifest as the checks step would have written it (a report edited behind the
    # manifest's back is damage, which `make assets` repairs by running the step again).
    checks = build / "checks" / "report.json"
    passing = checks.read_text()
    doc = json.loads(passing)
    doc["ok"] = False
    doc["packages"]["right"]["checks"]["coverage"]["ok"] = False
    checks.write_text(json.dumps(doc))
    record_manifest(tree)
    for _ in range(2):
        run = make(tree, "assets", MANO=pkl, RES=RES, GRASP_OBJECTS=GRASP_OBJECTS, LIBRARY_POSES=LIBRARY_POSES)
        assert run.returncode != 0 and "render: checks failed (right: coverage)" in run.stdout
    checks.write_text(passing)
    record_manifest(tree)
    run = make(tree, "assets", MANO=pkl, RES=RES, GRASP_OBJECTS=GRASP_OBJECTS, LIBRARY_POSES=LIBRARY_POSES)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "] ..." not in run.stderr       # nothing was rebuilt: the checks report is an input of the manifest only
