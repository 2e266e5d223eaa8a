"""Blender as an engine: import a package with Blender's own importers (or open the native .blend) and read back the
vertices it computes, and build the Blender-native rig.

Blender runs as `bpy` from PyPI in its own virtual environment (`make blender` makes `.venv-blender`; bpy 5.0 pins
numpy < 2, the project uses numpy 2), one subprocess per call: the scripts in export/blender/ read a JSON spec and
write an npz. Which Python runs them: $DARTHAND_BLENDER_PYTHON, else <repo>/.venv-blender/bin/python.

Blender's frame is Z up; its USD and glTF importers rotate Y-up assets by +90 degrees about X, so a point
(x, y, z) of the package is (x, -z, y) in Blender. `from_blender` undoes that.
"""

from __future__ import annotations

import json
import os
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darthand.errors import DarthandError

REPO_ROOT = Path(__file__).resolve().parents[3]
SCRIPTS = Path(__file__).resolve().parent / "blender"


class BlenderUnavailable(DarthandError):
    """Blender's Python (bpy) is not installed (`make blender` installs it)."""


@dataclass
class BlenderResult:
    """What Blender computed: vertices[label][object name] (N, 3) in the package's Y-up frame (metres), and `info`
    (import seconds, objects, materials, actions, bones, shape-key ranges; see blender/evaluate.py)."""

    vertices: dict
    info: dict


def blender_python() -> Path:
    """The Python that has bpy; BlenderUnavailable when there is none."""
    path = Path(os.environ.get("DARTHAND_BLENDER_PYTHON") or REPO_ROOT / ".venv-blender" / "bin" / "python")
    if not path.is_file():
        raise BlenderUnavailable(f"{path}: no Blender Python (run `make blender`, or set DARTHAND_BLENDER_PYTHON)")
    return path


def run_script(script: str, spec: dict, timeout: float = 900.0) -> None:
    """Run export/blender/<script> with `spec` (JSON) in Blender's Python; DarthandError with Blender's last output
    lines when it fails."""
    python = blender_python()
    with tempfile.TemporaryDirectory(prefix="darthand-blender-") as tmp:
        spec_path = Path(tmp) / "spec.json"
        spec_path.write_text(json.dumps(spec))
        proc = subprocess.run([str(python), str(SCRIPTS / script), str(spec_path)], capture_output=True, text=True,
                              timeout=timeout)
    if proc.returncode != 0:
        tail = " | ".join((proc.stderr or proc.stdout).strip().splitlines()[-5:])
        raise DarthandError(f"{spec.get('file') or spec.get('out')}: Blender failed ({script}): {tail[:600]}")


def blender_evaluate(path: str | Path, *, frames=(), actions: bool = False, action_frame: str = "first",
                     bone_poses: dict | None = None, timeout: float = 900.0) -> BlenderResult:
    """Import `path` (.usda/.usdc, .glb/.gltf, or open a .blend) with default options and return the evaluated
    vertices of every skinned mesh: at import ('import'), at scene `frames` ('frame_<f>'), at the first frame of
    every action (`actions`: 'action_<name>'; its last frame with action_frame='last'), and with bone rotations set
    ({label: {bone: (w, x, y, z)}})."""
    with tempfile.TemporaryDirectory(prefix="darthand-blender-") as tmp:
        out = Path(tmp) / "result.npz"
        spec = {"file": str(Path(path).resolve()), "out": str(out), "frames": [int(f) for f in frames],
                "actions": bool(actions), "action_frame": action_frame, "bone_poses": bone_poses or {}}
        run_script("evaluate.py", spec, timeout)
        with np.load(out) as z:
            info = json.loads(str(z["info"]))
            vertices: dict = {}
            for key in z.files:
                if key != "info":
                    label, name = key.split("/", 1)
                    vertices.setdefault(label, {})[name] = from_blender(z[key])
    return BlenderResult(vertices, info)


def from_blender(points: np.ndarray) -> np.ndarray:
    """Blender world points (..., 3), Z up, as the package's Y-up points: (x, y, z) -> (x, z, -y)."""
    p = np.asarray(points, dtype=np.float64)
    return np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1)


def to_blender(points: np.ndarray) -> np.ndarray:
    """The package's Y-up points (..., 3) in Blender's Z-up world: (x, y, z) -> (x, -z, y)."""
    p = np.asarray(points, dtype=np.float64)
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)


def blender_render(path: str | Path, out: str | Path, *, engine: str = "CYCLES", size=(640, 480), samples: int = 32,
                   gesture: str | None = None, texture: str | Path | None = None, camera: dict | None = None,
                   lens: float = 85.0, timeout: float = 900.0) -> Path:
    """Render `path` (.blend, glTF or USD) in Blender to the PNG `out` (see blender/render.py); camera {location,
    target} in the package's Y-up frame (default: looking at the back of a right hand from above)."""
    camera = camera or {"location": [0.0, 0.45, 0.05], "target": [-0.02, 0.0, 0.0]}
    spec = {"file": str(Path(path).resolve()), "out": str(Path(out).resolve()), "engine": engine,
            "size": list(size), "samples": int(samples), "gesture": gesture, "lens": lens,
            "texture": str(Path(texture).resolve()) if texture else None,
            "camera": {k: to_blender(np.asarray(v, dtype=np.float64)).tolist() for k, v in camera.items()}}
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    run_script("render.py", spec, timeout)
    return Path(out)
