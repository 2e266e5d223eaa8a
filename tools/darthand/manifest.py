"""build/manifest.json: every output with its size and sha256, per-step seconds, the model used, check results.

Hashes are reused from the previous manifest for files whose size and modification time are unchanged, so an
incremental `make assets` does not re-read gigabytes of textures.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from darthand import __version__
from darthand.fileio import sha256_file, write_json

SKIP_DIRS = {"steps", "bench"}
# Reports that stages write and the manifest gathers whole as check results: name -> path relative to build/.
CHECK_REPORTS = {
    "gestures": "template/gestures.json",
    "shapes": "template/shapes.json",
    "render": "checks/report.json",
    "validate": "validate/report.json",
}


def output_files(build: Path, manifest_path: Path) -> list[Path]:
    """Every regular file under build/, except the manifest, step records, benchmarks and hidden temporaries."""
    files = []
    for root, dirs, names in os.walk(build):
        rel_root = Path(root).relative_to(build)
        dirs[:] = sorted(d for d in dirs if not d.startswith(".") and not (rel_root == Path(".") and d in SKIP_DIRS))
        files += [Path(root) / n for n in sorted(names) if not n.startswith(".") and Path(root) / n != manifest_path]
    return files


def file_entries(build: Path, manifest_path: Path, previous: dict) -> list[dict]:
    """[{path, bytes, sha256}] with hashes reused when (bytes, mtime_ns) match the previous manifest."""
    old = {e["path"]: e for e in previous.get("outputs", [])}
    out = []
    for f in output_files(build, manifest_path):
        st = f.stat()
        rel = f.relative_to(build).as_posix()
        prev = old.get(rel)
        same = prev and prev.get("bytes") == st.st_size and prev.get("mtime_ns") == st.st_mtime_ns
        out.append({"path": rel, "bytes": st.st_size, "mtime_ns": st.st_mtime_ns,
                    "sha256": prev["sha256"] if same else sha256_file(f)})
    return out


def catalogue_checks(build: Path) -> dict:
    """The figures the texture and accessory catalogues record about themselves."""
    checks = {}
    textures = build / "textures" / "catalog.json"
    if textures.is_file():
        cat = json.loads(textures.read_text())
        checks["textures"] = {"variants": len(cat["entries"]), "resolution": cat["resolution"]}
    accessories = build / "accessories" / "catalog.json"
    if accessories.is_file():
        cat = json.loads(accessories.read_text())
        checks["accessories"] = {
            a["id"]: {"type": a["type"], "parent_joint": a["parent_joint"],
                      "max_penetration_mm": {k: a["max_penetration_mm"][k] for k in ("rest", "gestures", "poses")},
                      "max_axis_drift_mm": a.get("max_axis_drift_mm")}
            for a in cat["accessories"]}
    return checks


def model_used(build: Path) -> dict:
    source = build / "model" / "source.txt"
    info = {"source": source.read_text().strip() if source.is_file() else None}
    right = build / "model" / "right.npz"
    if right.is_file():
        from darthand.model.npz_io import load_npz
        m = load_npz(right)
        info.update(vertices=m.num_vertices, faces=m.num_faces, side=m.side, fixes=m.meta.get("fixes", []),
                    provenance=m.meta.get("provenance"))
    return info


def write_manifest(build: str | Path = "build", out: str | Path | None = None) -> dict:
    build = Path(build)
    out = Path(out) if out else build / "manifest.json"
    previous = json.loads(out.read_text()) if out.is_file() else {}
    records = {p.stem: json.loads(p.read_text()) for p in sorted((build / "steps").glob("*.json"))}
    steps = {name: r["seconds"] for name, r in records.items()}
    cpu = {name: r["cpu_seconds"] for name, r in records.items() if "cpu_seconds" in r}
    checks = {name: json.loads((build / rel).read_text()) for name, rel in CHECK_REPORTS.items()
              if (build / rel).is_file()}
    checks.update(catalogue_checks(build))
    manifest = {
        "darthand_version": __version__,
        "model": model_used(build),
        "steps_seconds": steps,
        "steps_cpu_seconds": cpu,
        "checks": checks,
        "failed_checks": failed_checks(checks),
        "outputs": file_entries(build, out, previous),
    }
    write_json(out, manifest)
    return manifest


def failed_checks(checks: dict) -> list[str]:
    """One line per check report that did not pass: the gesture guard's problems, render checks not ok,
    validation with errors or an unreadable package."""
    from darthand.template.gesture_checks import gesture_problems

    out = []
    if "gestures" in checks:
        out += [f"gestures: {line}" for line in gesture_problems(checks["gestures"].get("gestures", {}))]
    if "render" in checks and not checks["render"].get("ok", False):
        bad = [f"{side}: {name}" for side, pkg in checks["render"].get("packages", {}).items()
               for name, c in pkg.get("checks", {}).items() if isinstance(c, dict) and not c.get("ok", True)]
        out.append(f"render: checks failed ({', '.join(bad) or 'see checks/report.json'})")
    if "validate" in checks and checks["validate"].get("exit_code", 0) != 0:
        counts = checks["validate"].get("counts", {})
        out.append(f"validate: exit code {checks['validate']['exit_code']} ({counts.get('error', '?')} errors, "
                   "see validate/report.json)")
    return out


def check_manifest(path: str | Path) -> int:
    """`darthand manifest --check`: print each failed check of the manifest at `path`; 1 if any, else 0."""
    from darthand.fileio import read_json

    manifest = read_json(Path(path), "manifest")
    failures = failed_checks(manifest.get("checks", {}))
    for line in failures:
        print(f"{path}: {line}")
    return 1 if failures else 0
