"""Pose an exported .glb in a real engine, three.js (npm package `three`, installed at the repo root by `npm ci`),
and read back the vertex positions it computes.

three.js loads the file with its GLTFLoader, plays each animation to its end with an AnimationMixer and asks the
skinned mesh for every vertex (`SkinnedMesh.getVertexPosition`: morph targets, then bone skinning, as its shaders
do). This is how the project checks that what an engine computes from the asset equals what the rig computes.

Limits of the check, which are three.js's: it skins with JOINTS_0/WEIGHTS_0 only (4 influences; further sets are
ignored), and in Node it cannot decode images, so only untextured files are loaded here.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darthand.errors import DarthandError
from darthand.export.gltf_validator import REPO_ROOT, ValidatorUnavailable, node_package

_SCRIPT = r"""
import fs from "fs";
if (typeof globalThis.navigator === "undefined") globalThis.navigator = { userAgent: "node" };
const THREE = await import("three");
const { GLTFLoader } = await import("three/examples/jsm/loaders/GLTFLoader.js");
const [file, meshName] = process.argv.slice(1);
const data = fs.readFileSync(file);
const gltf = await new Promise((resolve, reject) =>
  new GLTFLoader().parse(data.buffer.slice(data.byteOffset, data.byteOffset + data.byteLength), "", resolve, reject));
const scene = gltf.scene;
let mesh = null;
scene.traverse((o) => {
  if (o.isSkinnedMesh && (o.name === meshName || o.parent?.name === meshName) && !mesh) mesh = o;
});
if (!mesh) { process.stderr.write(`no skinned mesh named ${meshName}`); process.exit(3); }
function positions() {
  scene.updateMatrixWorld(true);
  mesh.skeleton.update();
  const n = mesh.geometry.attributes.position.count, v = new THREE.Vector3(), out = new Array(3 * n);
  for (let i = 0; i < n; i++) {
    mesh.getVertexPosition(i, v).applyMatrix4(mesh.matrixWorld);
    out[3 * i] = v.x; out[3 * i + 1] = v.y; out[3 * i + 2] = v.z;
  }
  return out;
}
const poses = { "": positions() };
for (const clip of gltf.animations) {
  const mixer = new THREE.AnimationMixer(scene);
  const action = mixer.clipAction(clip);
  action.setLoop(THREE.LoopOnce);
  action.clampWhenFinished = true;
  action.play();
  mixer.setTime(clip.duration);
  poses[clip.name] = positions();
  mixer.stopAllAction();
  mixer.uncacheRoot(scene);
}
const ids = mesh.geometry.attributes._vertex_id;
process.stdout.write(JSON.stringify({ revision: THREE.REVISION, ids: ids ? Array.from(ids.array) : null, poses }));
"""


@dataclass
class EnginePoses:
    """Vertices three.js computes: `rest` (N, 3) and each animation's last frame {name: (N, 3)}; `vertex_ids` (N,)
    the model vertex of each (from _VERTEX_ID) or None."""

    revision: str
    rest: np.ndarray
    poses: dict
    vertex_ids: np.ndarray | None


def three_poses(path: str | Path, mesh_name: str, timeout: float = 600.0) -> EnginePoses:
    """Load a .glb in three.js and return the positions of the skinned mesh node `mesh_name` at rest and at the
    end of every animation. Raises ValidatorUnavailable when node or `three` is not installed."""
    node_package("three")
    proc = subprocess.run(["node", "--input-type=module", "-e", _SCRIPT, str(Path(path).resolve()), mesh_name],
                          capture_output=True, text=True, timeout=timeout, cwd=REPO_ROOT)
    if proc.returncode != 0:
        raise DarthandError(f"{path}: three.js could not evaluate the file: {proc.stderr.strip()[:500]}")
    out = json.loads(proc.stdout)
    arrays = {k: np.asarray(v, dtype=np.float64).reshape(-1, 3) for k, v in out["poses"].items()}
    ids = None if out["ids"] is None else np.asarray(out["ids"]).astype(np.int64)
    return EnginePoses(out["revision"], arrays.pop(""), arrays, ids)


__all__ = ["EnginePoses", "three_poses", "ValidatorUnavailable"]
