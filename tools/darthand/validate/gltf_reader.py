"""Read a glTF 2.0 asset (.glb, or .gltf with its buffers and images) into validate.asset's neutral form.

The document is read as plain JSON (pygltflib, the project's glTF writer, decodes no accessors, accepts a
truncated .glb and types nested objects only partly, which helps a writer but not a validator). Accessors are
decoded by `Buffers.accessor` with every offset, stride and count checked against its buffer before numpy looks
at it, and the GLB container's header and chunk lengths are checked against the file.

How darthand's glTF maps onto the neutral form (gltf_export's layout, and what a DCC round trip keeps):
    skin 0 -> Skeleton: joint names, parents (nearest joint ancestor), bind = inverse(inverseBindMatrices),
        rest = each joint node's local transform, root_parent = the global transform above the root joint;
    the first skinned mesh node -> the hand; other skinned mesh nodes -> skinned accessories (gloves); mesh nodes
        without a skin -> rigid accessories, bound to their nearest joint ancestor (None: unbound), their points
        moved by the node's global rest transform into the hand's frame;
    morph targets -> dense BlendShapes named by mesh.extras.targetNames; images -> TextureRefs (colour: base
        colour and emissive textures; data: metallic-roughness, normal, occlusion);
    ids: KHR_materials_variants names (or the single skin material's extras `darthand.texture`) are texture ids,
        accessory node names are accessory ids.
"""

from __future__ import annotations

import base64
import os
import stat
import struct
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from darthand.errors import DarthandError
from darthand.fileio import file_kind, parse_json
from darthand.model.rotations import quaternion_to_matrix
from darthand.validate.asset import BlendShape, Limits, Mesh, Package, Skeleton, Skin, TextureRef
from darthand.validate.findings import Finding, finding

COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
GLB_MAGIC, JSON_CHUNK, BIN_CHUNK = b"glTF", 0x4E4F534A, 0x004E4942
VARIANTS = "KHR_materials_variants"
MAX_JSON_DEPTH = 256     # glTF documents nest about 8 deep; extras may nest more, within reason


class Unreadable(Exception):
    """The file is not a readable glTF: the message is one line."""


class Malformed(Exception):
    """An accessor, buffer view or node reference is inconsistent (a `file.malformed` finding)."""


class TooLarge(Exception):
    """An array above the limits (a `file.array-too-large` finding)."""


class Unavailable(Exception):
    """Data in a buffer that could not be loaded; the buffer's finding already says why."""


# ------------------------------------------------------------------------------------------------ files


def load_document(path: Path, limits: Limits) -> tuple[dict, bytes | None]:
    """(the glTF JSON, GLB binary chunk or None). Unreadable for anything that is not a glTF 2.0 file."""
    size = path.stat().st_size
    if path.suffix.lower() == ".glb":
        text, blob = glb_chunks(path, size, limits)
    else:
        if size > limits.max_json_bytes:
            raise Unreadable(f"{size} bytes of JSON, above the limit of {limits.max_json_bytes}")
        text, blob = path.read_bytes(), None
    try:
        data = parse_json(text, path.name, "glTF document", max_depth=MAX_JSON_DEPTH)
    except DarthandError as e:
        raise Unreadable(f"not glTF: {str(e).split(': ', 1)[-1]}") from None
    version = str(_dict(data, "asset").get("version", "")) if isinstance(data, dict) else ""
    if not version.startswith("2."):
        raise Unreadable("not a glTF 2.0 asset (no asset.version 2.x)")
    return data, blob


def _list(d, key: str) -> list:
    v = d.get(key) if isinstance(d, dict) else None
    return v if isinstance(v, list) else []


def _dict(d, key: str) -> dict:
    v = d.get(key) if isinstance(d, dict) else None
    return v if isinstance(v, dict) else {}


def _int(d, key: str, default=None):
    v = d.get(key, default) if isinstance(d, dict) else default
    if v is not None and (not isinstance(v, int) or isinstance(v, bool)):
        raise Malformed(f"field {key!r} is {v!r}, not an integer")
    return v


def glb_chunks(path: Path, size: int, limits: Limits) -> tuple[bytes, bytes | None]:
    """The JSON and BIN chunks of a .glb, after checking its header against the file."""
    with open(path, "rb") as f:
        header = f.read(20)
        if len(header) < 20 or header[:4] != GLB_MAGIC:
            raise Unreadable("not a GLB file (no 'glTF' header)")
        version, length, json_length, json_type = struct.unpack("<IIII", header[4:20])
        if version != 2:
            raise Unreadable(f"GLB version {version}, expected 2")
        if length != size:
            raise Unreadable(f"truncated or padded: the GLB header says {length} bytes, the file has {size}")
        if json_type != JSON_CHUNK or 20 + json_length > size:
            raise Unreadable("the GLB's first chunk is not a complete JSON chunk")
        if json_length > limits.max_json_bytes:
            raise Unreadable(f"{json_length} bytes of JSON, above the limit of {limits.max_json_bytes}")
        text = f.read(json_length)
        rest = f.read(8)
        if len(rest) < 8:
            return text, None
        bin_length, bin_type = struct.unpack("<II", rest)
        if bin_type != BIN_CHUNK or 28 + json_length + bin_length > size:
            raise Unreadable("the GLB's second chunk is not a complete BIN chunk")
        return text, f.read(bin_length)


# ------------------------------------------------------------------------------------------------ accessors


class Buffers:
    """The document's buffers (bytes, or None when unavailable) and checked accessor decoding."""

    def __init__(self, doc: dict, blob: bytes | None, base: Path, root: Path, limits: Limits):
        self.doc, self.limits = doc, limits
        self.data: list[bytes | None] = []
        self.findings: list[Finding] = []
        for i, buf in enumerate(_list(doc, "buffers")):
            self.data.append(self._load(i, buf, blob, base, root))

    def _load(self, i: int, buf: dict, blob: bytes | None, base: Path, root: Path) -> bytes | None:
        uri = buf.get("uri") if isinstance(buf, dict) else None
        if uri is None:
            if i == 0 and blob is not None:
                return blob
            self.findings.append(finding("file.malformed", f"/buffers/{i}", f"buffer {i} has no URI and there is no "
                                         "GLB binary chunk for it"))
            return None
        uri = str(uri)
        if uri.startswith("data:"):
            return decode_data_uri(uri)
        target, problem = package_file(uri, base, root)
        if problem or target is None:
            self.findings.append(finding("gltf.buffer-path", f"/buffers/{i}", f"buffer {uri!r} {problem}"))
            return None
        if target.stat().st_size > self.limits.max_elements * 4:
            self.findings.append(finding("file.array-too-large", f"/buffers/{i}", f"buffer {uri!r} is "
                                         f"{target.stat().st_size} bytes"))
            return None
        return target.read_bytes()

    def view_bytes(self, index) -> bytes:
        views = _list(self.doc, "bufferViews")
        if not isinstance(index, int) or not 0 <= index < len(views):
            raise Malformed(f"bufferView {index} does not exist")
        view = views[index]
        buffer = _int(view, "buffer", -1)
        if not 0 <= buffer < len(self.data):
            raise Malformed(f"bufferView {index} reads buffer {buffer}, which does not exist")
        data = self.data[buffer]
        if data is None:
            raise Unavailable(f"bufferView {index} reads buffer {buffer}, which is unavailable")
        start, length = _int(view, "byteOffset", 0), _int(view, "byteLength", 0)
        if start < 0 or length < 0 or start + length > len(data):
            raise Malformed(f"bufferView {index} ({start} + {length} bytes) runs past the end of buffer {buffer} "
                            f"({len(data)} bytes)")
        return data[start:start + length]

    def accessor(self, index, max_count: int | None = None) -> np.ndarray:
        """Accessor `index` as a (count, width) array (normalised integers as floats in [0, 1] / [-1, 1])."""
        accessors = _list(self.doc, "accessors")
        if not isinstance(index, int) or not 0 <= index < len(accessors):
            raise Malformed(f"accessor {index} does not exist")
        acc = accessors[index]
        dtype, width = COMPONENTS.get(_int(acc, "componentType")), WIDTH.get(acc.get("type"))
        count = _int(acc, "count", -1)
        if dtype is None or width is None or count < 0:
            raise Malformed(f"accessor {index} has componentType {acc.get('componentType')}, type "
                            f"{acc.get('type')}, count {acc.get('count')}")
        limit = self.limits.max_elements if max_count is None else max_count
        if count > limit or count * width > self.limits.max_elements:
            raise TooLarge(f"accessor {index} has {count} elements, above the limit of {limit}")
        dtype = np.dtype(dtype)
        out = self._dense(index, acc, count, dtype, width)
        sparse = _dict(acc, "sparse")
        if sparse and _int(sparse, "count", 0):
            out = self._apply_sparse(index, sparse, count, out, dtype, width)
        if acc.get("normalized") and out.dtype.kind in "iu":
            out = np.maximum(out / np.iinfo(out.dtype).max, -1.0)
        return out

    def _dense(self, index: int, acc: dict, count: int, dtype: np.dtype, width: int) -> np.ndarray:
        view = _int(acc, "bufferView")
        if view is None or not count:
            return np.zeros((count, width), dtype)
        data = self.view_bytes(view)
        stride = _int(_list(self.doc, "bufferViews")[view], "byteStride", 0) or dtype.itemsize * width
        offset = _int(acc, "byteOffset", 0)
        need = offset + stride * (count - 1) + dtype.itemsize * width
        if offset < 0 or need > len(data):
            raise Malformed(f"accessor {index} needs {need} bytes of bufferView {view}, which has {len(data)}")
        return np.ndarray((count, width), dtype, buffer=data, offset=offset, strides=(stride, dtype.itemsize)).copy()

    def _apply_sparse(self, index: int, sparse: dict, count: int, out: np.ndarray, dtype: np.dtype,
                      width: int) -> np.ndarray:
        n = _int(sparse, "count", 0)
        indices, values = _dict(sparse, "indices"), _dict(sparse, "values")
        idx_type = np.dtype(COMPONENTS.get(_int(indices, "componentType"), np.uint32))
        idx_data = self.view_bytes(_int(indices, "bufferView"))[_int(indices, "byteOffset", 0):]
        val_data = self.view_bytes(_int(values, "bufferView"))[_int(values, "byteOffset", 0):]
        if n < 0 or n > count or n * idx_type.itemsize > len(idx_data) or n * dtype.itemsize * width > len(val_data):
            raise Malformed(f"accessor {index}'s sparse data runs past its buffer views")
        rows = np.frombuffer(idx_data, idx_type, n).astype(np.int64)
        if len(rows) and (rows.min() < 0 or rows.max() >= count):
            raise Malformed(f"accessor {index}'s sparse indices leave 0..{count - 1}")
        out = out.copy()
        out[rows] = np.frombuffer(val_data, dtype, n * width).reshape(n, width)
        return out


def decode_data_uri(uri: str) -> bytes | None:
    head, _, payload = uri.partition(",")
    try:
        return base64.b64decode(payload) if head.endswith(";base64") else unquote(payload).encode("latin-1")
    except (ValueError, UnicodeEncodeError):
        return None


def package_file(uri: str, base: Path, root: Path) -> tuple[Path | None, str]:
    """The file a relative URI names, or None and why it is not acceptable (absolute, outside, missing)."""
    rel = unquote(uri)
    if ":" in rel.split("/")[0] or os.path.isabs(rel):
        return None, "is absolute"
    lexical = Path(os.path.normpath(base / rel))
    root_n = Path(os.path.normpath(root))
    if root_n not in lexical.parents:
        return None, "leads outside the package folder"
    if not os.path.lexists(lexical):
        return None, "does not exist"
    real, real_root = Path(os.path.realpath(lexical)), Path(os.path.realpath(root))
    if real_root not in real.parents:
        return None, f"is a link to {real}, outside the package folder"
    try:
        mode = os.stat(lexical).st_mode
    except OSError:
        return None, "does not exist"
    if not stat.S_ISREG(mode):
        return None, f"is {file_kind(mode)}, not a regular file (not opened)"
    return lexical, ""


# ------------------------------------------------------------------------------------------------ the document


def read_gltf(path: Path, limits: Limits = Limits()) -> tuple[Package, list[Finding]]:
    """The package of a .glb / .gltf and the reader's findings. Raises Unreadable."""
    doc, blob = load_document(path, limits)
    extras = _dict(_dict(_dict(doc, "asset"), "extras"), "darthand")
    side = extras.get("side") if extras.get("side") in ("right", "left") else None
    pkg = Package(path, "glb" if path.suffix.lower() == ".glb" else "gltf", path.parent, side=side)
    buffers = Buffers(doc, blob, path.parent, path.parent, limits)
    reader = GltfReader(doc, buffers, pkg, limits, claims=extras.get("correctives") == "full")
    return pkg, buffers.findings + reader.run()


class GltfReader:
    """Fills a Package from the document, step by step (hierarchy, skins, meshes, images, ids); a step that meets
    inconsistent data leaves a finding and the others still run."""

    def __init__(self, doc: dict, buffers: Buffers, pkg: Package, limits: Limits, claims: bool):
        self.doc, self.buffers, self.pkg, self.limits, self.claims = doc, buffers, pkg, limits, claims
        self.nodes = [n if isinstance(n, dict) else {} for n in _list(doc, "nodes")]
        self.findings: list[Finding] = []
        self.parents: list[int] = []
        self.joints: list[int] = []
        self._globals: dict[int, np.ndarray] = {}

    def run(self) -> list[Finding]:
        if self.guard("/nodes", self.read_hierarchy) is None:
            return self.findings
        for i, skin in enumerate(_list(self.doc, "skins")):
            self.guard(f"/skins/{i}", self.read_skeleton, i, skin)
        self.read_meshes()
        self.read_images()
        self.guard("/extensions", self.read_ids)
        return self.findings

    def guard(self, where: str, fn, *args):
        """fn(*args) (True when it returns None), or None when it failed: inconsistent or oversized data becomes a
        finding instead of an exception."""
        try:
            result = fn(*args)
            return True if result is None else result
        except Malformed as e:
            self.findings.append(finding("file.malformed", where, str(e)))
        except TooLarge as e:
            self.findings.append(finding("file.array-too-large", where, str(e)))
        except Unavailable:
            pass
        except (TypeError, ValueError, KeyError, IndexError, AttributeError) as e:   # JSON of unexpected shape
            self.findings.append(finding("file.malformed", where, f"unexpected glTF structure ({type(e).__name__}: "
                                         f"{e})"))
        return None

    def read_hierarchy(self) -> None:
        self.parents = node_parents(self.nodes)
        skins = _list(self.doc, "skins")
        self.joints = list(_list(skins[0], "joints")) if skins else []

    # -------------------------------------------------------------------------------------------- transforms

    def local(self, i: int) -> np.ndarray:
        """(4, 4) column-vector local transform of node i."""
        n = self.nodes[i]
        if "matrix" in n:
            m = np.asarray(n["matrix"], dtype=np.float64)
            if m.shape != (16,):
                raise Malformed(f"node {i} has a matrix of {m.size} numbers")
            return m.reshape(4, 4).T
        m = np.eye(4)
        if "rotation" in n:
            x, y, z, w = np.asarray(n["rotation"], dtype=np.float64).reshape(4)
            q = np.array([w, x, y, z])
            m[:3, :3] = quaternion_to_matrix(q) if np.isfinite(q).all() and (q != 0).any() else np.nan
        if "scale" in n:
            m[:3, :3] = m[:3, :3] * np.asarray(n["scale"], dtype=np.float64).reshape(3)[None, :]
        if "translation" in n:
            m[:3, 3] = np.asarray(n["translation"], dtype=np.float64).reshape(3)
        return m

    def global_(self, i: int) -> np.ndarray:
        if i not in self._globals:
            p = self.parents[i]
            self._globals[i] = (self.global_(p) if p >= 0 else np.eye(4)) @ self.local(i)
        return self._globals[i]

    def joint_ancestor(self, i: int, joints: list[int]) -> int:
        """Index in `joints` of node i's nearest ancestor that is a joint (-1 if none)."""
        p = self.parents[i]
        while p >= 0:
            if p in joints:
                return joints.index(p)
            p = self.parents[p]
        return -1

    # -------------------------------------------------------------------------------------------- skeleton

    def read_skeleton(self, s: int, skin: dict) -> None:
        joints = _list(skin, "joints")
        if any(not isinstance(j, int) or not 0 <= j < len(self.nodes) for j in joints):
            raise Malformed(f"skin {s} names a joint node that does not exist")
        J = len(joints)
        if skin.get("inverseBindMatrices") is not None:
            ibm = self.buffers.accessor(skin["inverseBindMatrices"])
            if ibm.shape != (J, 16):
                raise Malformed(f"skin {s}'s inverseBindMatrices has {len(ibm)} matrices of {ibm.shape[1]} numbers "
                                f"for {J} joints")
            ibm = ibm.astype(np.float64).reshape(J, 4, 4).transpose(0, 2, 1)
        else:
            ibm = np.tile(np.eye(4), (J, 1, 1))
        with np.errstate(all="ignore"):
            try:
                bind = np.linalg.inv(ibm)
            except np.linalg.LinAlgError:
                bind = np.full_like(ibm, np.nan)
        parents = np.array([self.joint_ancestor(j, joints) for j in joints], dtype=np.int64)
        above = self.global_(self.parents[joints[0]]) if J and self.parents[joints[0]] >= 0 else None
        names = [str(self.nodes[j].get("name") or f"node{j}") for j in joints]
        rest = np.array([self.local(j) for j in joints]).reshape(J, 4, 4)
        self.pkg.skeletons.append(Skeleton(f"/skins/{s}", names, parents, bind, rest, root_parent=above))

    # -------------------------------------------------------------------------------------------- meshes

    def read_meshes(self) -> None:
        meshes = _list(self.doc, "meshes")
        hand_found = False
        for n, node in enumerate(self.nodes):
            m = node.get("mesh")
            if m is None:
                continue
            if not isinstance(m, int) or not 0 <= m < len(meshes):
                self.findings.append(finding("file.malformed", f"/nodes/{n}", f"node {n} draws mesh {m}, which "
                                             "does not exist"))
                continue
            skinned = node.get("skin") is not None
            role = "hand" if skinned and not hand_found else "accessory"
            hand_found = hand_found or role == "hand"
            # an accessory's catalogue id: the node's extras (darthand writes it there; its name has the side
            # prefix), else its name
            name = str(_dict(_dict(node, "extras"), "darthand").get("accessory") or node.get("name") or f"node{n}")
            if role == "accessory":
                self.pkg.accessory_ids.append((name, f"/nodes/{n}"))
            for p, prim in enumerate(_list(meshes[m], "primitives")):
                where = f"/meshes/{m}/primitives/{p}"
                # the hand node's further primitives are the forearm cap (darthand writes it as primitive 1)
                kind = "cap" if role == "hand" and p > 0 else role
                mesh = self.guard(where, self.read_primitive, n, node, meshes[m], prim, where, kind, name)
                if isinstance(mesh, Mesh):
                    self.pkg.meshes.append(mesh)

    def read_primitive(self, n: int, node: dict, gmesh: dict, prim: dict, where: str, role: str,
                       name: str) -> Mesh | None:
        attrs = _dict(prim, "attributes")
        if attrs.get("POSITION") is None:
            raise Malformed(f"{where} has no POSITION")
        points = self.buffers.accessor(attrs["POSITION"], self.limits.max_points).astype(np.float64)
        if points.shape[1] != 3:
            raise Malformed(f"POSITION of {where} is not VEC3")
        indices = None
        if prim.get("indices") is not None:
            indices = self.buffers.accessor(prim["indices"], 3 * self.limits.max_faces).reshape(-1)
        faces = triangles(_int(prim, "mode", 4), indices, len(points))
        if faces is None:
            return None      # points or lines: nothing for the surface rules
        skinned = node.get("skin") is not None
        if not skinned and role == "accessory":
            g = self.global_(n)
            points = points @ g[:3, :3].T + g[:3, 3]
        mesh = Mesh(where, role, points, faces, claims_correctives=self.claims and role == "hand")
        if role == "accessory":
            mesh.accessory_id = name
            if not skinned:
                j = self.joint_ancestor(n, self.joints)
                mesh.rigid_joint = j if j >= 0 else None
        if attrs.get("TEXCOORD_0") is not None:
            mesh.uvs = self.buffers.accessor(attrs["TEXCOORD_0"]).astype(np.float64)
            mesh.uv_faces = faces
        if skinned:
            mesh.skin = self.read_skin(attrs, _int(node, "skin"), where)
        names = _list(_dict(gmesh, "extras"), "targetNames")
        for t, target in enumerate(_list(prim, "targets")):
            index = target.get("POSITION") if isinstance(target, dict) else None
            if index is None:
                continue
            shape = str(names[t]) if t < len(names) else f"target{t}"
            mesh.blend_shapes.append(BlendShape(shape, f"{where}/targets/{t}",
                                                self.buffers.accessor(index).astype(np.float64)))
        return mesh

    def read_skin(self, attrs: dict, skin_index: int, where: str) -> Skin | None:
        sets, k = [], 0
        while attrs.get(f"JOINTS_{k}") is not None or attrs.get(f"WEIGHTS_{k}") is not None:
            ji, wi = attrs.get(f"JOINTS_{k}"), attrs.get(f"WEIGHTS_{k}")
            if ji is None or wi is None:
                raise Malformed(f"{where} has JOINTS_{k} and WEIGHTS_{k} unpaired")
            sets.append((self.buffers.accessor(ji), self.buffers.accessor(wi)))
            k += 1
        if not sets:
            return None
        skins = _list(self.doc, "skins")
        num_joints = len(_list(skins[skin_index], "joints")) if 0 <= skin_index < len(skins) else 0
        return Skin(np.hstack([s[0] for s in sets]).astype(np.int64),
                    np.hstack([s[1] for s in sets]).astype(np.float64), False, num_joints)

    # -------------------------------------------------------------------------------------------- images

    def read_images(self) -> None:
        roles = image_roles(self.doc)
        for i, image in enumerate(_list(self.doc, "images")):
            ref = self.guard(f"/images/{i}", self.read_image, i, image, roles.get(i, "unknown"))
            if isinstance(ref, TextureRef):
                self.pkg.textures.append(ref)

    def read_image(self, i: int, image: dict, role: str) -> TextureRef:
        uri = str(image.get("uri") or "")
        ref = TextureRef(f"/images/{i}", uri, role=role)
        if image.get("bufferView") is not None:
            ref.data = self.buffers.view_bytes(image["bufferView"])
        elif uri.startswith("data:"):
            ref.data = decode_data_uri(uri) or b""
        elif uri:
            ref.asset = unquote(uri)
            if not (":" in ref.asset.split("/")[0] or os.path.isabs(ref.asset)):
                ref.file = Path(os.path.normpath(self.pkg.root / ref.asset))
        return ref

    def read_ids(self) -> None:
        variants = _list(_dict(_dict(self.doc, "extensions"), VARIANTS), "variants")
        if variants:
            for k, v in enumerate(variants):
                if isinstance(v, dict) and v.get("name"):
                    self.pkg.texture_ids.append((str(v["name"]), f"/extensions/{VARIANTS}/variants/{k}"))
            return
        hand = next((m for m in self.pkg.meshes if m.role == "hand"), None)
        if hand is None:
            return
        mesh_index, prim_index = (int(x) for x in hand.path.split("/")[2::2])
        material = _list(_list(self.doc, "meshes")[mesh_index], "primitives")[prim_index].get("material")
        materials = _list(self.doc, "materials")
        if isinstance(material, int) and 0 <= material < len(materials):
            texture = _dict(_dict(materials[material], "extras"), "darthand").get("texture")
            name = str(materials[material].get("name") or "")
            if texture is None and name.startswith("skin_"):
                texture = name[len("skin_"):]        # packages written before the texture id moved to extras
            if texture is not None:
                self.pkg.texture_ids.append((str(texture), f"/materials/{material}"))


def node_parents(nodes: list[dict]) -> list[int]:
    """(N,) parent node of each node (-1 for roots); Malformed for bad child indices, two parents or cycles."""
    parents = [-1] * len(nodes)
    for i, node in enumerate(nodes):
        for c in _list(node, "children"):
            if not isinstance(c, int) or not 0 <= c < len(nodes):
                raise Malformed(f"node {i} lists child {c}, which does not exist")
            if parents[c] != -1 or c == i:
                raise Malformed(f"node {c} has more than one parent")
            parents[c] = i
    for i in range(len(nodes)):
        p, steps = parents[i], 0
        while p >= 0:
            p, steps = parents[p], steps + 1
            if steps > len(nodes):
                raise Malformed(f"node {i} is inside a cycle of children")
    return parents


def triangles(mode: int, indices: np.ndarray | None, count: int) -> np.ndarray | None:
    """(F, 3) triangles of a primitive of `mode` (4 list, 5 strip, 6 fan; None for points and lines)."""
    idx = np.arange(count, dtype=np.int64) if indices is None else indices.astype(np.int64)
    if mode == 4:
        if len(idx) % 3:
            raise Malformed(f"{len(idx)} triangle indices is not a multiple of 3")
        return idx.reshape(-1, 3)
    if mode in (5, 6):
        k = np.arange(max(0, len(idx) - 2))
        if mode == 6:
            return np.stack([np.full_like(k, idx[0] if len(idx) else 0), idx[k + 1], idx[k + 2]], axis=1)
        odd = k % 2 == 1             # strips alternate winding
        return np.stack([idx[k], np.where(odd, idx[k + 2], idx[k + 1]), np.where(odd, idx[k + 1], idx[k + 2])], 1)
    return None


def image_roles(doc: dict) -> dict[int, str]:
    """{image index: 'color' | 'data'} from the materials' texture slots."""
    textures = _list(doc, "textures")
    roles: dict[int, str] = {}

    def mark(info: dict, role: str) -> None:
        index = info.get("index")
        if not isinstance(index, int) or not 0 <= index < len(textures):
            return
        source = textures[index].get("source")
        if isinstance(source, int) and (role == "color" or source not in roles):
            roles[source] = role

    for m in _list(doc, "materials"):
        pbr = _dict(m, "pbrMetallicRoughness")
        mark(_dict(pbr, "baseColorTexture"), "color")
        mark(_dict(pbr, "metallicRoughnessTexture"), "data")
        mark(_dict(m, "emissiveTexture"), "color")
        mark(_dict(m, "normalTexture"), "data")
        mark(_dict(m, "occlusionTexture"), "data")
    return roles
