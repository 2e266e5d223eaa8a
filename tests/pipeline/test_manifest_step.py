"""The pipeline plumbing: step records and the manifest."""

import hashlib
import json
import os
import sys
from pathlib import Path

import jsonschema

from darthand.manifest import write_manifest
from darthand.step import run_step

SCHEMA = json.loads((Path(__file__).resolve().parents[2] / "schemas" / "manifest.schema.json").read_text())


def test_manifest_lists_outputs_with_true_hashes(tmp_path):
    build = tmp_path / "build"
    (build / "textures").mkdir(parents=True)
    (build / "textures" / "a.png").write_bytes(b"abc")
    (build / "textures" / ".a.png.tmp").write_bytes(b"half")       # a temporary is not an output
    (build / "bench").mkdir()
    (build / "bench" / "x.json").write_text("{}")
    assert run_step("demo", [sys.executable, "-c", "pass"], steps_dir=build / "steps") == 0
    m = write_manifest(build)
    jsonschema.validate(m, SCHEMA)
    assert [e["path"] for e in m["outputs"]] == ["textures/a.png"]
    assert m["outputs"][0]["sha256"] == hashlib.sha256(b"abc").hexdigest()
    assert set(m["steps_seconds"]) == {"demo"}
    assert json.loads((build / "manifest.json").read_text()) == m


def test_manifest_rehashes_changed_files_only(tmp_path):
    build = tmp_path / "build"
    build.mkdir()
    f = build / "x.bin"
    f.write_bytes(b"one")
    write_manifest(build)
    # Same size and mtime: the old hash is reused (proved by planting a wrong one); changed: rehashed.
    m = json.loads((build / "manifest.json").read_text())
    m["outputs"][0]["sha256"] = "0" * 64
    (build / "manifest.json").write_text(json.dumps(m))
    assert write_manifest(build)["outputs"][0]["sha256"] == "0" * 64
    f.write_bytes(b"two!")
    os.utime(f, ns=(1, 1))
    assert write_manifest(build)["outputs"][0]["sha256"] == hashlib.sha256(b"two!").hexdigest()


def test_failed_step_leaves_no_record(tmp_path):
    steps = tmp_path / "steps"
    assert run_step("ok", [sys.executable, "-c", "pass"], steps_dir=steps) == 0
    assert run_step("ok", [sys.executable, "-c", "raise SystemExit(3)"], steps_dir=steps) == 3
    assert not (steps / "ok.json").exists()


def test_atomic_outputs_get_normal_permissions(tmp_path):
    from darthand.fileio import write_bytes

    old = os.umask(0o022)
    try:
        write_bytes(tmp_path / "f.bin", b"x")
    finally:
        os.umask(old)
    assert (tmp_path / "f.bin").stat().st_mode & 0o777 == 0o644


def test_atomic_hard_link_over_the_same_file_leaves_no_temporary(tmp_path):
    from darthand.fileio import atomic_path

    src = tmp_path / "src.png"
    src.write_bytes(b"png")
    for _ in range(2):      # the second time, dst is already a link to src
        with atomic_path(tmp_path / "dst.png") as tmp:
            tmp.unlink()
            os.link(src, tmp)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dst.png", "src.png"]
