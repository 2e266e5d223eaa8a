"""build/manifest.json: every output with its size and sha256, per-step seconds, the model used, check results; and
`verify_outputs`, which finds the outputs that no longer match it (a truncated texture, a deleted file).

Hashes are reused from the previous manifest for files whose size and modification time are unchanged, so an
incremental `make assets` does not re-read gigabytes of textures.
"""

from __future__ import annotations

import os
from pathlib import Path

from darthand import __version__
from darthand.errors import InputError
from darthand.fileio import read_json, sha256_file, write_json

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
        same = prev is not None and prev.get("bytes") == st.st_size and prev.get("mtime_ns") == st.st_mtime_ns
        out.append({"path": rel, "bytes": st.st_size, "mtime_ns": st.st_mtime_ns,
                    "sha256": prev["sha256"] if prev is not None and same else sha256_file(f)})
    return out


def catalogue_checks(build: Path) -> dict:
    """The figures the texture, accessory, object and grasp catalogues record about themselves."""
    checks = {}
    textures = build / "textures" / "catalog.json"
    if textures.is_file():
        cat = _read(textures)
        checks["textures"] = {"variants": len(cat["entries"]), "resolution": cat["resolution"]}
    accessories = build / "accessories" / "catalog.json"
    if accessories.is_file():
        cat = _read(accessories)
        checks["accessories"] = {
            a["id"]: {"type": a["type"], "parent_joint": a["parent_joint"],
                      "max_penetration_mm": {k: a["max_penetration_mm"][k] for k in ("rest", "gestures", "poses")},
                      "max_axis_drift_mm": a.get("max_axis_drift_mm")}
            for a in cat["accessories"]}
    objects = build / "objects" / "catalog.json"
    if objects.is_file():
        cat = _read(objects)
        checks["objects"] = {"objects": len(cat["objects"]), "skipped": [s["id"] for s in cat["skipped"]]}
    grasps = build / "grasps" / "catalog.json"
    if grasps.is_file():
        cat = _read(grasps)
        checks["grasps"] = {**cat["counts"], **{k: v for k, v in cat["figures"].items() if k.endswith("_mm")}}
    return checks


def _read(path: Path):
    """A JSON file of the build (strict, depth-checked: fileio.read_json)."""
    return read_json(path, "build record", max_bytes=256 << 20)


def model_used(build: Path) -> dict:
    source = build / "model" / "source.txt"
    info: dict = {"source": source.read_text().strip() if source.is_file() else None}
    right = build / "model" / "right.npz"
    if right.is_file():
        from darthand.model.npz_io import load_npz  # lazy: verify and manifest --check, run by every `make assets`,
                                                     # stay at 0.15 s without the model stack
        m = load_npz(right)
        info.update(vertices=m.num_vertices, faces=m.num_faces, side=m.side, fixes=m.meta.get("fixes", []),
                    provenance=m.meta.get("provenance"))
    return info


def write_manifest(build: str | Path = "build", out: str | Path | None = None) -> dict:
    build = Path(build)
    if not build.is_dir():
        raise InputError(f"{build}: no such build folder")
    out = Path(out) if out else build / "manifest.json"
    previous = _read(out) if out.is_file() else {}
    previous = previous if isinstance(previous, dict) and isinstance(previous.get("outputs"), list) else {}
    records = {p.stem: _read(p) for p in sorted((build / "steps").glob("*.json"))}
    steps = {name: r["seconds"] for name, r in records.items()}
    cpu = {name: r["cpu_seconds"] for name, r in records.items() if "cpu_seconds" in r}
    checks = {name: _read(build / rel) for name, rel in CHECK_REPORTS.items() if (build / rel).is_file()}
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
    from darthand.template.gesture_problems import gesture_problems  # lazy: as load_npz above

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
    manifest = read_json(Path(path), "manifest")
    failures = failed_checks(manifest.get("checks", {}))
    for line in failures:
        print(f"{path}: {line}")
    return 1 if failures else 0


# ------------------------------------------------------------------------------------------------ verifying

# The make target of the step that writes each part of build/ (longest prefix wins): making it older than its
# prerequisites makes `make assets` run that step again, which rewrites what was damaged.
STEP_TARGETS = {
    "model": "model/right.npz",
    "template": "template/gestures.json",
    "textures": "textures/catalog.json",
    "accessories": "accessories/catalog.json",
    "objects": "objects/catalog.json",
    "grasps": "grasps/catalog.json",
    "poses": "poses/right.json",
    "usd/right": "usd/right/right.usda",
    "usd/left": "usd/left/left.usda",
    "gltf/right.glb": "gltf/right.glb",
    "gltf/left.glb": "gltf/left.glb",
    "gltf/right": "gltf/right/right.gltf",
    "gltf/left": "gltf/left/left.gltf",
    "blender/right.blend": "blender/right.blend",
    "blender/left.blend": "blender/left.blend",
    "checks": "checks/report.json",
    "validate": "validate/report.json",
}


def verify_outputs(build: str | Path = "build", full: bool = False) -> list[tuple[str, str]]:
    """[(path relative to build/, what is wrong)] for every output of the manifest that is missing or differs from
    it: by size, else by sha256 when its modification time changed (every file's sha256 with `full`)."""
    build = Path(build)
    path = build / "manifest.json"
    if not path.is_file():
        raise InputError(f"{path}: no manifest to verify against (run make assets)")
    manifest = read_json(path, "build manifest", max_bytes=256 << 20)
    entries = manifest.get("outputs") if isinstance(manifest, dict) else None
    if not isinstance(entries, list):
        raise InputError(f"{path}: field 'outputs' missing: not a darthand build manifest")
    damaged = []
    for e in entries:
        rel = e.get("path") if isinstance(e, dict) else None
        if not isinstance(rel, str) or rel.startswith("/") or ".." in Path(rel).parts:
            raise InputError(f"{path}: an output path {str(rel)[:60]!r} is not inside the build folder")
        f = build / rel
        try:
            st = f.stat()
        except OSError:
            damaged.append((rel, "missing"))
            continue
        if st.st_size != e.get("bytes"):
            damaged.append((rel, f"{st.st_size} bytes, the manifest says {e.get('bytes')}"))
        elif (full or st.st_mtime_ns != e.get("mtime_ns")) and sha256_file(f) != e.get("sha256"):
            damaged.append((rel, "content differs from the manifest's sha256"))
    return damaged


def step_target(rel: str) -> str | None:
    """The make target of the step that writes `rel` (relative to build/), None for files no step owns."""
    parts = rel.split("/")
    for k in range(len(parts), 0, -1):
        target = STEP_TARGETS.get("/".join(parts[:k]))
        if target:
            return target
    return None


def invalidate(build: str | Path, damaged: list[tuple[str, str]]) -> list[str]:
    """Remove the damaged files and date the targets of their steps back to 1970, so `make assets` runs those
    steps (and the ones after them) again; returns the targets."""
    build = Path(build)
    targets = sorted({t for rel, _ in damaged if (t := step_target(rel))})
    for rel, _ in damaged:
        (build / rel).unlink(missing_ok=True)
    for t in targets:
        if (build / t).is_file():
            os.utime(build / t, ns=(0, 0))
    return targets
