"""An independent glTF 2.0 skinning evaluator (the truth the exporter is checked against), and its own tests.

It reads a written .glb/.gltf back with pygltflib and evaluates the spec's formulas with scipy's rotations and
plain numpy, sharing no code with the writer:

    local(node)      = T(translation) R(rotation, x y z w) S(scale)   (or node.matrix)
    global(node)     = global(parent) local(node)
    jointMatrix_j    = global(joint_j) inverseBindMatrix_j
    morphed position = POSITION + sum_k weight_k target_k.POSITION
    skinned position = sum_sets sum_c WEIGHTS_s[c] jointMatrix[JOINTS_s[c]] morphed position
    animation        = LINEAR samplers: lerp for translations and weights, slerp for rotations

The tests at the bottom check the evaluator itself on hand-written glTF documents with known answers.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib as gl
from scipy.spatial.transform import Rotation, Slerp

_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


class GltfFile:
    """A glTF file read back: the pygltflib document plus decoded accessors."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.doc = gl.GLTF2().load(str(self.path))
        self._buffers = {}

    def buffer(self, i: int) -> bytes:
        if i not in self._buffers:
            uri = self.doc.buffers[i].uri
            self._buffers[i] = self.doc.binary_blob() if uri is None else (self.path.parent / uri).read_bytes()
        return self._buffers[i]

    def accessor(self, i: int) -> np.ndarray:
        """(count, width) float64 or integer array of accessor i: strides, sparse substitution and normalisation
        applied (spec: no bufferView means zeros, then sparse values replace the listed elements)."""
        acc = self.doc.accessors[i]
        dt = np.dtype(_DTYPES[acc.componentType]).newbyteorder("<")
        width = _WIDTH[acc.type]
        if acc.bufferView is None:
            arr = np.zeros((acc.count, width), dtype=dt)
        else:
            arr = self._view(acc.bufferView, acc.byteOffset or 0, dt, acc.count, width)
        if acc.sparse is not None:
            sparse = _obj(acc.sparse)
            ind, val = _obj(sparse["indices"]), _obj(sparse["values"])
            idx = self._view(ind["bufferView"], ind.get("byteOffset") or 0,
                             np.dtype(_DTYPES[ind["componentType"]]).newbyteorder("<"), sparse["count"], 1)[:, 0]
            assert (np.diff(idx.astype(np.int64)) > 0).all(), "sparse indices must strictly increase"
            arr[idx] = self._view(val["bufferView"], val.get("byteOffset") or 0, dt, sparse["count"], width)
        if acc.normalized:
            return arr.astype(np.float64) / np.iinfo(dt).max
        return arr.astype(np.float64) if dt.kind == "f" else arr

    def _view(self, view_index: int, offset: int, dt: np.dtype, count: int, width: int) -> np.ndarray:
        view = self.doc.bufferViews[view_index]
        stride = view.byteStride or dt.itemsize * width
        start = (view.byteOffset or 0) + offset
        assert start + stride * (count - 1) + dt.itemsize * width <= (view.byteOffset or 0) + view.byteLength
        return np.ndarray((count, width), dtype=dt, buffer=self.buffer(view.buffer), offset=start,
                          strides=(stride, dt.itemsize)).copy()

    def attr(self, primitive, name: str):
        """Accessor data of a primitive attribute, or None."""
        a = primitive.attributes
        idx = a.get(name) if isinstance(a, dict) else getattr(a, name, None)
        return None if idx is None else self.accessor(idx)

    def node_index(self, name: str) -> int:
        return next(i for i, n in enumerate(self.doc.nodes) if n.name == name)

    def parents(self) -> dict[int, int]:
        return {c: p for p, n in enumerate(self.doc.nodes) for c in (n.children or [])}


def _obj(x) -> dict:
    """A pygltflib object or a plain dict, as a dict."""
    return x if isinstance(x, dict) else vars(x)


def local_matrix(node, trs: dict | None = None) -> np.ndarray:
    """4x4 local matrix of a node; `trs` overrides translation / rotation / scale (from an animation)."""
    trs = trs or {}
    if node.matrix is not None and not trs:
        return np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T  # stored column-major
    t = np.asarray(trs.get("translation", node.translation if node.translation is not None else [0, 0, 0]), float)
    q = np.asarray(trs.get("rotation", node.rotation if node.rotation is not None else [0, 0, 0, 1]), float)
    s = np.asarray(trs.get("scale", node.scale if node.scale is not None else [1, 1, 1]), float)
    m = np.eye(4)
    m[:3, :3] = Rotation.from_quat(q).as_matrix() * s[None, :]   # scipy quaternions are (x, y, z, w) too
    m[:3, 3] = t
    return m


def global_matrices(f: GltfFile, overrides: dict[int, dict] | None = None) -> np.ndarray:
    """(nodes, 4, 4) global matrices with optional per-node TRS overrides."""
    overrides = overrides or {}
    parents = f.parents()
    out = np.zeros((len(f.doc.nodes), 4, 4))
    done = np.zeros(len(f.doc.nodes), bool)

    def visit(i):
        if not done[i]:
            local = local_matrix(f.doc.nodes[i], overrides.get(i))
            out[i] = local if i not in parents else visit(parents[i]) @ local
            done[i] = True
        return out[i]

    for i in range(len(f.doc.nodes)):
        visit(i)
    return out


def sample_animation(f: GltfFile, name: str, t: float) -> tuple[dict[int, dict], dict[int, np.ndarray]]:
    """TRS overrides per node and morph weights per node of animation `name` at time t (LINEAR samplers)."""
    anim = next(a for a in f.doc.animations if a.name == name)
    trs, weights = {}, {}
    for ch in anim.channels:
        smp = anim.samplers[ch.sampler]
        assert smp.interpolation in (None, "LINEAR")
        times = f.accessor(smp.input)[:, 0]
        out = f.accessor(smp.output)
        path, node = ch.target.path, ch.target.node
        if path == "weights":
            out = out.reshape(len(times), -1)
        t_clamped = float(np.clip(t, times[0], times[-1]))
        if path == "rotation":
            value = out[-1] if len(times) == 1 else Slerp(times, Rotation.from_quat(out))(t_clamped).as_quat()
        else:
            value = np.array([np.interp(t_clamped, times, out[:, c]) for c in range(out.shape[1])])
        if path == "weights":
            weights[node] = value
        else:
            trs.setdefault(node, {})[path] = value
    return trs, weights


def skinned_positions(f: GltfFile, node_index: int, globals_: np.ndarray, morph_weights=None) -> np.ndarray:
    """(N, 3) world positions of a skinned mesh node's first primitive (the spec's skinning formula)."""
    node = f.doc.nodes[node_index]
    mesh = f.doc.meshes[node.mesh]
    prim = mesh.primitives[0]
    pos = f.attr(prim, "POSITION")
    w = np.asarray(mesh.weights if morph_weights is None else morph_weights, dtype=np.float64) \
        if prim.targets else np.zeros(0)
    for k, target in enumerate(prim.targets or []):
        idx = target["POSITION"] if isinstance(target, dict) else target.POSITION
        pos = pos + w[k] * f.accessor(idx)
    skin = f.doc.skins[node.skin]
    ibm = f.accessor(skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
    joint_mats = globals_[skin.joints] @ ibm
    blended = np.zeros((len(pos), 4, 4))
    s = 0
    while (j := f.attr(prim, f"JOINTS_{s}")) is not None:
        wt = f.attr(prim, f"WEIGHTS_{s}")
        for c in range(4):
            blended += wt[:, c, None, None] * joint_mats[j[:, c].astype(int)]
        s += 1
    assert s > 0, "mesh is not skinned"
    return np.einsum("nij,nj->ni", blended[:, :3, :3], pos) + blended[:, :3, 3]


def static_positions(f: GltfFile, node_index: int, globals_: np.ndarray) -> np.ndarray:
    """(N, 3) world positions of a non-skinned mesh node's first primitive."""
    prim = f.doc.meshes[f.doc.nodes[node_index].mesh].primitives[0]
    pos = f.attr(prim, "POSITION")
    g = globals_[node_index]
    return pos @ g[:3, :3].T + g[:3, 3]


def posed_mesh(f: GltfFile, mesh_node: str, animation: str | None = None, t: float = 0.0) -> np.ndarray:
    """Positions of the skinned node `mesh_node` in the rest state or at time t of an animation."""
    trs, weights = sample_animation(f, animation, t) if animation else ({}, {})
    i = f.node_index(mesh_node)
    return skinned_positions(f, i, global_matrices(f, trs), weights.get(i))


# ------------------------------------------------------------------------------------------------ evaluator tests


def _tiny_skinned_glb(path: Path, quat_xyzw, weights_target: float) -> None:
    """Two joints (root at origin, child at x = 1), two vertices bound fully to the child, one morph target."""
    doc = gl.GLTF2(scene=0, scenes=[gl.Scene(nodes=[0, 2])])
    doc.nodes = [gl.Node(name="root", children=[1]), gl.Node(name="child", translation=[1, 0, 0],
                                                                rotation=list(quat_xyzw)),
                 gl.Node(name="mesh", mesh=0, skin=0)]
    blob = bytearray()

    def acc(arr, kind):
        arr = np.ascontiguousarray(arr)
        doc.bufferViews.append(gl.BufferView(buffer=0, byteOffset=len(blob), byteLength=arr.nbytes))
        blob.extend(arr.tobytes())
        ctype = {np.float32: gl.FLOAT, np.uint8: gl.UNSIGNED_BYTE}[arr.dtype.type]
        doc.accessors.append(gl.Accessor(bufferView=len(doc.bufferViews) - 1, componentType=ctype,
                                         count=len(arr), type=kind))
        return len(doc.accessors) - 1

    pos = acc(np.array([[2, 0, 0], [1, 1, 0]], np.float32), gl.VEC3)
    joints = acc(np.array([[1, 0, 0, 0]] * 2, np.uint8), gl.VEC4)
    wts = acc(np.array([[1, 0, 0, 0]] * 2, np.float32), gl.VEC4)
    target = acc(np.array([[0, 0, 1], [0, 0, 0]], np.float32), gl.VEC3)
    ibm = np.tile(np.eye(4), (2, 1, 1))
    ibm[1, :3, 3] = [-1, 0, 0]
    ibm_acc = acc(ibm.transpose(0, 2, 1).reshape(2, 16).astype(np.float32), gl.MAT4)
    doc.meshes = [gl.Mesh(primitives=[gl.Primitive(attributes=gl.Attributes(POSITION=pos, JOINTS_0=joints,
                                                                            WEIGHTS_0=wts),
                                                   targets=[gl.Attributes(POSITION=target)])],
                          weights=[weights_target])]
    doc.skins = [gl.Skin(joints=[0, 1], inverseBindMatrices=ibm_acc)]
    doc.buffers = [gl.Buffer(byteLength=len(blob))]
    doc.set_binary_blob(bytes(blob))
    doc.save_binary(str(path))


def test_evaluator_rotates_about_the_child_joint(tmp_path):
    # 90 degrees about +Z at the child joint (x = 1): (2, 0, 0) -> (1, 1, 0) and (1, 1, 0) -> (0, 0, 0).
    q = [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)]
    _tiny_skinned_glb(tmp_path / "t.glb", q, 0.0)
    f = GltfFile(tmp_path / "t.glb")
    got = skinned_positions(f, 2, global_matrices(f))
    np.testing.assert_allclose(got, [[1, 1, 0], [0, 0, 0]], atol=1e-7)


def test_evaluator_adds_morph_targets_before_skinning(tmp_path):
    # Morph moves vertex 0 by +Z 0.5 in the bind pose; the rotation about Z keeps that offset along Z.
    q = [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)]
    _tiny_skinned_glb(tmp_path / "t.glb", q, 0.5)
    f = GltfFile(tmp_path / "t.glb")
    got = skinned_positions(f, 2, global_matrices(f))
    np.testing.assert_allclose(got[0], [1, 1, 0.5], atol=1e-7)
    # Rotating 90 degrees about +X instead turns the morph's +Z offset into -Y.
    q = [np.sin(np.pi / 4), 0, 0, np.cos(np.pi / 4)]
    _tiny_skinned_glb(tmp_path / "u.glb", q, 0.5)
    f = GltfFile(tmp_path / "u.glb")
    got = skinned_positions(f, 2, global_matrices(f))
    np.testing.assert_allclose(got[0], [2, -0.5, 0], atol=1e-7)


def test_evaluator_local_matrix_composes_trs():
    node = gl.Node(translation=[1, 2, 3], rotation=[0, 0, 1, 0], scale=[2, 2, 2])  # 180 deg about Z, scale 2
    m = local_matrix(node)
    np.testing.assert_allclose(m @ [1, 0, 0, 1], [-1, 2, 3, 1], atol=1e-12)
