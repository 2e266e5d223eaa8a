"""The command: exit codes 0 / 1 / 2, text and --json output (against schemas/validation_report.schema.json),
--out, package folders, nothing written to the checked files, the rule table kept in step with the schema and
rules.md, every rule covered by a fixture, and --render while the renderer's checks do not exist yet."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import jsonschema
import pytest
from corpus import copy_package, edit_glb
from test_gltf_corpus import GLB_CASES, GLTF_CASES
from test_usd_corpus import CASES as USD_CASES

from darthand.errors import DarthandError
from darthand.cli import main
from darthand.validate.findings import RULES, Finding
from darthand.validate.run import validate_paths

REPO = Path(__file__).resolve().parents[2]
SCHEMA = json.loads((REPO / "schemas" / "validation_report.schema.json").read_text())


def run(argv, capsys) -> tuple[int, str]:
    code = main(["validate", *[str(a) for a in argv]])
    return code, capsys.readouterr().out


@pytest.fixture()
def broken_glb(good_glb, tmp_path) -> Path:
    path = copy_package(good_glb, tmp_path / "broken")
    edit_glb(path, GLB_CASES["weights-sum"][1])
    return path


@pytest.fixture()
def garbage(tmp_path) -> Path:
    path = tmp_path / "not_a_hand.usda"
    path.write_text("this is not a USD layer\n")
    return path


def test_exit_codes(good_usd, good_glb, broken_glb, garbage, capsys):
    assert run([good_usd, good_glb], capsys)[0] == 0
    assert run([good_usd, broken_glb], capsys)[0] == 1
    assert run([good_usd, broken_glb, garbage], capsys)[0] == 2
    code, out = run([garbage], capsys)
    assert code == 2 and "not a valid usda layer" in out


def test_text_report_has_a_line_per_package_and_finding(good_usd, broken_glb, capsys):
    code, out = run([good_usd, broken_glb], capsys)
    lines = out.strip().splitlines()
    assert lines[0].startswith(f"{good_usd / 'right.usda'} (usd): clean")
    assert any(line.startswith(f"{broken_glb} (glb): PROBLEMS") for line in lines)
    assert any(re.match(r"^  error\s+rig\.weights-sum\s+/meshes/0/primitives/0: ", line) for line in lines)
    assert lines[-1] == "2 packages: 1 clean, 1 with problems, 0 unreadable"


def test_json_report_follows_the_schema(good_usd, broken_glb, garbage, tmp_path, capsys):
    out_file = tmp_path / "report.json"
    code, out = run([good_usd, broken_glb, garbage, "--json", "--out", out_file], capsys)
    report = json.loads(out)
    jsonschema.Draft202012Validator(SCHEMA).validate(report)
    assert json.loads(out_file.read_text()) == report
    assert report["exit_code"] == code == 2
    assert [p["status"] for p in report["packages"]] == ["clean", "problems", "unreadable"]
    rules = {f["rule"] for p in report["packages"] for f in p["findings"]}
    assert {"rig.weights-sum", "file.unreadable"} <= rules


def test_schema_rejects_unknown_rules_and_severities():
    validator = jsonschema.Draft202012Validator(SCHEMA)
    package = {"path": "x.glb", "format": "glb", "status": "problems", "seconds": 0.1,
               "counts": {"error": 1, "warning": 0, "info": 0}, "findings": []}
    report = {"format": "darthand-validation-report", "version": 1, "exit_code": 1,
              "counts": {"error": 1, "warning": 0, "info": 0}, "packages": [package]}
    for rule, severity, ok in (("mesh.winding", "error", True), ("usd.usdSkelValidators:SkelBindingApiValidator",
                                                                  "warning", True),
                               ("gltf.ACCESSOR_INVALID_FLOAT", "error", True), ("mesh.made-up", "error", False),
                               ("mesh.winding", "fatal", False)):
        package["findings"] = [{"rule": rule, "severity": severity, "path": "/", "message": "m"}]
        assert validator.is_valid(report) == ok, (rule, severity)


def test_rule_table_schema_and_rules_md_agree():
    anyof = SCHEMA["$defs"]["rule"]["anyOf"]
    assert set(anyof[0]["enum"]) == set(RULES)
    table = (REPO / "tools" / "darthand" / "validate" / "rules.md").read_text()
    rows = dict(re.findall(r"^\| `([a-z]+\.[a-z-]+)` \| (error|warning|info) \|", table, flags=re.M))
    assert rows == {rule: r.severity for rule, r in RULES.items()}


def test_every_rule_has_a_broken_fixture():
    """Each of darthand's rules is exercised by a fixture of the corpus (or by the named tests below)."""
    fixtures = {rule for rule, _ in USD_CASES.values()} | {rule for rule, _ in GLB_CASES.values()} | \
        {rule for rule, _ in GLTF_CASES.values()}
    elsewhere = {
        "file.unreadable": "test_unreadable_files_exit_2",
        "file.array-too-large": "test_huge_arrays_are_refused",
        "gltf.validator-unavailable": "test_missing_khronos_validator_is_an_info",
        "render.failed": "test_render_findings_from_the_renderers_checks",
        "render.unsupported": "test_render_with_the_reference_renderer",
    }
    assert set(RULES) - fixtures - set(elsewhere) == set()


def test_package_folders_are_expanded(good_usd, good_gltf, tmp_path):
    report = validate_paths([good_usd, good_gltf.parent])
    assert [Path(p.path).name for p in report.packages] == ["right.usda", "right.gltf"]
    empty = tmp_path / "empty"
    empty.mkdir()
    report = validate_paths([empty, tmp_path / "nothing_here.glb"])
    assert report.exit_code == 2 and [f.rule for f in report.findings] == ["file.unreadable"] * 2


def test_relative_paths_are_judged_like_absolute_ones(good_usd, good_gltf, monkeypatch):
    monkeypatch.chdir(good_usd.parent)
    assert validate_paths([Path(good_usd.name)]).findings == []
    monkeypatch.chdir(good_gltf.parent.parent)
    report = validate_paths([Path(good_gltf.parent.name) / good_gltf.name])
    assert report.exit_code == 0 and not [f for f in report.findings if f.rule.startswith("tex.")]


def snapshot(paths) -> dict:
    """(bytes hash, mtime_ns, mode) of every file under the paths."""
    import hashlib

    out = {}
    for root in paths:
        files = [root] if root.is_file() else sorted(p for p in root.rglob("*") if p.is_file())
        for f in files:
            st = f.stat()
            out[str(f)] = (hashlib.sha256(f.read_bytes()).hexdigest(), st.st_mtime_ns, st.st_mode)
    return out


def test_checked_files_are_never_modified(good_usd, good_glb, good_gltf, tmp_path, capsys):
    from darthand.export.usdz import export_usdz

    usdz = tmp_path / "right.usdz"
    export_usdz(good_usd, usdz)
    targets = [good_usd, good_glb, good_gltf.parent, usdz]
    before = snapshot(targets)
    run([*targets, "--deep", "--json"], capsys)
    assert snapshot(targets) == before           # same files (none added), same bytes, mtimes and modes


def test_no_traceback_from_the_command_line(good_usd, broken_glb, garbage, tmp_path):
    """A separate process, as a user runs it: findings and one-line errors on stdout, nothing on stderr."""
    truncated = tmp_path / "truncated.glb"
    truncated.write_bytes(broken_glb.read_bytes()[:3000])
    exe = Path(sys.executable).with_name("darthand")
    proc = subprocess.run([str(exe), "validate", str(good_usd), str(broken_glb), str(garbage),
                           str(truncated)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stdout + proc.stderr and proc.stderr == ""
    assert "GLB header says" in proc.stdout


def test_missing_khronos_validator_is_an_info(good_glb, monkeypatch):
    from darthand.export import gltf_validator

    def unavailable(*args, **kwargs):
        raise gltf_validator.ValidatorUnavailable("node is not installed (test)")

    monkeypatch.setattr(gltf_validator, "validator_package", unavailable)
    report = validate_paths([good_glb])
    assert report.exit_code == 0
    assert [(f.rule, f.severity) for f in report.findings] == [("gltf.validator-unavailable", "info")]


# ------------------------------------------------------------------------------------------------ --render


def test_render_findings_from_the_renderers_checks(good_usd):
    """The adapter from checks (path, out_dir) -> [{id, passed, message, severity?}] to findings, with a stand-in
    for the renderer."""
    from darthand.validate.rules_render import render_findings

    seen = {}

    def check_asset(path, out_dir):
        seen["args"] = (path, out_dir.is_dir())
        return [{"id": "coverage", "passed": True, "message": "fine"},
                {"id": "Mask Empty", "passed": False, "message": "the hand covers 0 pixels"},
                {"id": "labels_in_frame", "passed": False, "severity": "warning",
                 "message": "keypoint 4 is outside the image"}]

    found = render_findings(good_usd, check_asset)
    assert seen["args"] == (good_usd, True)
    assert found == [Finding("render.mask-empty", "error", good_usd.name, "the hand covers 0 pixels"),
                     Finding("render.labels_in_frame", "warning", good_usd.name, "keypoint 4 is outside the image")]

    def failing(path, out_dir):
        raise DarthandError(f"{path}: cannot render")

    (f,) = render_findings(good_usd, failing)
    assert f.rule == "render.failed" and f.severity == "error"


def test_render_with_the_reference_renderer(good_usd, good_glb, model, tmp_path, monkeypatch):
    """--render opens the package with the renderer (finding the model in <dir>/model/<side>.npz, as in build/),
    runs its checks once and reports exactly the checks that failed; glTF is not rendered."""
    from darthand.model.npz_io import save_npz
    from darthand.render import checks

    build = tmp_path / "build"
    pkg = copy_package(good_usd, build / "usd")
    save_npz(model, build / "model" / "right.npz")
    calls = []
    original = checks.check_package

    def spy(source, **kwargs):
        result = original(source, **kwargs)
        calls.append(result)
        return result

    monkeypatch.setattr(checks, "check_package", spy)
    report = validate_paths([pkg, good_glb], render=True)
    (result,) = calls
    assert len(result["checks"]) >= 4                       # the renderer's checks ran (not an empty result)
    failed = {f"render.{name}" for name, c in result["checks"].items() if not c["ok"]}
    usd, glb = report.packages
    assert {f.rule for f in usd.findings if f.rule.startswith("render.")} == failed
    assert all(f.message and f.severity == "error" for f in usd.findings if f.rule.startswith("render."))
    assert ("render.unsupported", "info") in {(f.rule, f.severity) for f in glb.findings}
