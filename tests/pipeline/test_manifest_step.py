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
    assert set(m["steps_seconds"]) == set(m["steps_cpu_seconds"]) == {"demo"}
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


def _checks(gestures_between: int = 0, render_ok: bool = True, validate_exit: int = 0) -> dict:
    entry = {"finite": True, "inverted_faces": 0, "between_fingers_faces": gestures_between,
             "between": {"thumb-index": gestures_between} if gestures_between else {}}
    return {"gestures": {"gestures": {"ok": entry}},
            "render": {"ok": render_ok, "packages": {"left": {"checks": {"uv_seams": {"ok": render_ok}}}}},
            "validate": {"exit_code": validate_exit, "counts": {"error": 2 if validate_exit else 0}},
            "textures": {"variants": 325, "resolution": 64}}


def test_failed_checks_name_each_failing_report():
    from darthand.manifest import failed_checks

    assert failed_checks(_checks()) == []
    lines = failed_checks(_checks(gestures_between=3, render_ok=False, validate_exit=1))
    assert len(lines) == 3
    assert lines[0].startswith("gestures: gesture 'ok': 3 faces where digits intersect (thumb-index 3)")
    assert lines[1] == "render: checks failed (left: uv_seams)"
    assert lines[2] == "validate: exit code 1 (2 errors, see validate/report.json)"


def test_manifest_check_exits_1_while_a_recorded_check_fails(tmp_path, capsys):
    """`darthand manifest --check` (what `make assets` runs last): 1 and one line per failure, every time."""
    from darthand.cli import main

    build = tmp_path / "build"
    (build / "checks").mkdir(parents=True)
    report = build / "checks" / "report.json"
    report.write_text(json.dumps(_checks(render_ok=False)["render"]))
    m = write_manifest(build)
    jsonschema.validate(m, SCHEMA)
    assert m["failed_checks"] == ["render: checks failed (left: uv_seams)"]
    cli = ["manifest", "--build", str(build), "--check"]
    for _ in range(2):
        assert main(cli) == 1 and "render: checks failed (left: uv_seams)" in capsys.readouterr().out
    report.write_text(json.dumps(_checks()["render"]))
    write_manifest(build)
    assert main(cli) == 0 and capsys.readouterr().out == ""
    (build / "manifest.json").write_text("{")
    assert main(cli) == 2 and "manifest.json: " in capsys.readouterr().err


def test_step_record_says_when_it_started(tmp_path):
    import time

    before = time.time()
    assert run_step("demo", [sys.executable, "-c", "pass"], steps_dir=tmp_path / "steps") == 0
    record = json.loads((tmp_path / "steps" / "demo.json").read_text())
    assert before - 0.01 <= record["started"] <= time.time()
    assert record["started"] + record["seconds"] <= time.time() + 0.01


def test_make_assets_per_run_commands_import_no_stage(tmp_path):
    """`verify` and `manifest` (run by every `make assets`, a no-op rebuild included) parse their arguments without
    importing the stages' heavy dependencies (OpenUSD, SciPy's optimiser), which cost about 1.3 s per command."""
    import subprocess

    code = ("import sys; from darthand.cli import main; "
            f"rc = main(['verify', '--build', {str(tmp_path)!r}, '--repair']); "
            "rc |= main(['manifest', '--build', " + repr(str(tmp_path)) + "]); "
            "heavy = [m for m in ('pxr', 'scipy.optimize', 'darthand.export.usd_asset') if m in sys.modules]; "
            "print(heavy); sys.exit(rc or bool(heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
    assert (tmp_path / "manifest.json").is_file()


def test_a_no_op_make_assets_imports_no_numerics(tmp_path):
    """What every `make assets` runs on a finished build -- `verify --repair`, then `manifest --check` when the manifest
    changed -- reads the manifest (its gesture report included) without importing NumPy, SciPy or MeshLab: their
    imports were most of a no-op rebuild's second."""
    import subprocess

    (tmp_path / "template").mkdir()
    report = {"gestures": {"fist": {"finite": True, "inverted_faces": 0, "between_fingers_faces": 0,
                                    "finger_palm_faces": 3, "between": {"palm-index": 3}}}}
    (tmp_path / "template" / "gestures.json").write_text(json.dumps(report))
    (tmp_path / "manifest.json").write_text(json.dumps(
        {"outputs": [], "checks": {"gestures": report}, "failed_checks": []}, indent=1))
    code = ("import sys; from darthand.cli import main; "
            f"rc = main(['verify', '--build', {str(tmp_path)!r}, '--repair']); "
            f"rc |= main(['manifest', '--build', {str(tmp_path)!r}, '--check']); "
            "heavy = [m for m in ('numpy', 'scipy', 'pymeshlab', 'pxr') if m in sys.modules]; "
            "print(heavy); sys.exit(rc or bool(heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
