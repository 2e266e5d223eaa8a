"""Surface maps baked into UV space once per (model, resolution): rest position, normal, semantic label, coverage,
anatomical fields and a bank of solid-noise fields, for every covered texel; plus the padding map.

Only covered texels are stored (N of them, as flat indices into the res x res image, row-major, row 0 at the top
= v of 1). A texel is covered if its centre lies in a UV triangle, or within `MARGIN` texels of one (its values
then come from the nearest point of that triangle: a gutter of true surface values, so that bilinear lookups on
either side of a seam see the same surface). Every other texel is filled by push-pull: the
coverage-weighted average pyramid of the stored texels is pulled back down, so empty space holds smooth averages of
the islands around it. Engines that build their own mipmaps from the PNGs (Blender's EEVEE, three.js, game
engines) then average islands with that smooth fill instead of with the sharp colour edges a nearest-texel
(Voronoi) dilation leaves where the regions of two islands meet, which showed as bright specks along UV seams
(see `padding`; its block structure is built once per bake and shared by every image).

Cached in `bake_<res>.npz` next to the textures, keyed by a hash of the model's geometry, UVs and labels.
"""

from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import atomic_path
from darthand.model.hand_model import HandModel
from darthand.model.mirror import mirror_model
from darthand.model.topology import vertex_normals
from darthand.textures import anatomy, noise, padding
from darthand.textures.raster import rasterize
from darthand.model.regions import ensure_face_labels, face_geometry, skeleton

BAKE_VERSION = 7  # 7: no stored fill map (padding.Layout is built from `texel` on load)
# The modules whose code decides what a bake holds: their source is part of the cache key, so editing them
# invalidates cached bakes by itself.
BAKE_MODULES = ("anatomy", "bake", "curves", "noise", "raster", "model/regions")
MARGIN = 2.0  # texels of true surface values around every island
NOISE_SEED = 0x0DA27  # the noise bank is part of the bake: fixed, so every catalogue shares it
# band: (fields, feature size in metres, octaves). Variants mix two fields of a band at a random angle, so
# each gets its own pattern for two multiply-adds.
NOISE_BANK = {
    "low": (4, 0.030, 2),
    "mid": (4, 0.008, 2),
    "fine": (3, 0.0014, 2),
    "pore": (2, 0.00045, 1),
}


@dataclass(frozen=True, eq=False)
class Bake:
    """Baked maps of one model at one resolution (N covered texels).

    res       texture size (square)
    texel     (N,) int64, flat index row * res + col, ascending
    face      (N,) int32, the face each texel samples
    inside    (N,) bool, the texel centre is inside its face (False: gutter texel within MARGIN)
    position  (N, 3) float32, rest-pose surface point, metres
    normal    (N, 3) float32, interpolated unit vertex normal
    label     (N,) int8, layout.FACE_LABELS index: the face's label, nails refined to the smooth nail plates
    fields    name -> (N,) arrays: anatomy fields (see anatomy.anatomy_fields) and noise bank fields
              'noise_<band><k>' (unit standard deviation; float16 on disk, float32 once loaded)
    mesh      vertices (V, 3), faces (F, 3), face_labels (F,), uvs (T, 2), faces_uv (F, 3), joints (16, 3),
              tips (5, 3), vertex_normals (V, 3): the model the bake came from (float64)
    key       hash of the inputs (see `bake_key`)
    """

    res: int
    texel: np.ndarray
    face: np.ndarray
    inside: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    label: np.ndarray
    fields: dict = field(default_factory=dict)
    mesh: dict = field(default_factory=dict)
    key: str = ""

    @property
    def num_texels(self) -> int:
        return int(len(self.texel))

    def coverage(self, gutter: bool = False) -> np.ndarray:
        """(res, res) bool image: texel centres inside a face (with `gutter`: also the margin texels)."""
        img = np.zeros(self.res * self.res, bool)
        img[self.texel if gutter else self.texel[self.inside]] = True
        return img.reshape(self.res, self.res)

    def label_image(self) -> np.ndarray:
        """(res, res) uint8: label index of covered texels (inside faces), 255 elsewhere."""
        img = np.full(self.res * self.res, 255, np.uint8)
        img[self.texel[self.inside]] = self.label[self.inside].astype(np.uint8)
        return img.reshape(self.res, self.res)

    def image(self, values: np.ndarray) -> np.ndarray:
        """Per-texel uint8 values (N,) or (N, C) -> (res, res[, C]) uint8 image: the stored texels exact, every other
        texel the rounded mean of the stored texels in the smallest aligned 2^L x 2^L block around it (push-pull on
        the mip pyramid's own blocks: a box mipmap of the result mixes, in each block, only that block's stored
        texels, never colours from outside it; see `padding`)."""
        v = np.asarray(values)
        return padding.pad(self.layout, v.reshape(len(v), -1)).reshape((self.res, self.res) + v.shape[1:])

    @functools.cached_property
    def layout(self) -> padding.Layout:
        """The stored texels' block structure, shared by every image of this bake."""
        return padding.Layout.of(self.texel, self.res)

    def noise(self, band: str, rng: np.random.Generator) -> np.ndarray:
        """A random unit-variance mix of two of a band's noise fields, cos(a) F_i + sin(a) F_j (independent
        fields, so the mix is again unit variance with the same spectrum); (N,) float32."""
        count = NOISE_BANK[band][0]
        i, j = rng.choice(count, size=2, replace=False)
        a = rng.uniform(0.0, 2.0 * np.pi)
        out = np.float32(np.cos(a)) * self.fields[f"noise_{band}{i}"]
        out += np.float32(np.sin(a)) * self.fields[f"noise_{band}{j}"]
        return out


def prepare_model(model: HandModel) -> HandModel:
    """The model the bake needs: a right hand (a left one is mirrored: same UVs, so its textures are the
    right hand's, mirrored) with face labels (derived where missing); UVs must be present."""
    if not model.has_uvs:
        raise InputError(f"{model.meta.get('source', 'model')}: field 'uvs' missing: give the model an atlas first "
                         "(darthand.model.atlas.ensure_uvs)")
    if model.side == "left":
        model = mirror_model(model)
    return ensure_face_labels(model)


def source_digest(modules) -> str:
    """sha256 of the source of darthand modules, in order: names of this stage's modules ('anatomy') or paths
    within the package ('model/regions')."""
    h = hashlib.sha256()
    for name in modules:
        h.update((Path(__file__).parents[int("/" in name)] / f"{name}.py").read_bytes())
    return h.hexdigest()


def bake_key(model: HandModel, res: int) -> str:
    """sha256 over everything a bake depends on: the model's geometry, UVs and labels, the resolution, and the
    code that bakes."""
    h = hashlib.sha256(f"bake v{BAKE_VERSION} res {int(res)} {source_digest(BAKE_MODULES)}".encode())
    for arr in (model.v_template, model.faces, model.uvs, model.faces_uv, model.face_labels, model.tip_ids,
                np.asarray(model.J_regressor @ model.v_template)):
        a = np.ascontiguousarray(arr)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def bake(model: HandModel, res: int) -> Bake:
    """Bake `model` (with UVs) into a `res` x `res` texture layout."""
    res = int(res)
    if res < 16 or res > 16384:
        raise InputError(f"texture resolution {res} outside 16..16384")
    model = prepare_model(model)
    key = bake_key(model, res)
    assert model.uvs is not None and model.faces_uv is not None and model.face_labels is not None  # prepare_model
    uv = model.uvs[model.faces_uv]  # (F, 3, 2)
    tri = np.stack([uv[..., 0] * res, (1.0 - uv[..., 1]) * res], -1)
    frags = rasterize(tri, res, res, margin=MARGIN)
    if len(frags.pixel) == 0:
        raise InputError(f"{model.meta.get('source', 'model')}: field 'uvs' covers no texel of a {res}x{res} texture")
    verts, faces = model.v_template, model.faces
    vnormals = vertex_normals(verts, faces)
    corners = faces[frags.face]
    position = np.einsum("nk,nki->ni", frags.bary, verts[corners])
    normal = np.einsum("nk,nki->ni", frags.bary, vnormals[corners])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    skel = skeleton(model)
    texel_size = np.sqrt(face_geometry(verts, faces)[2].sum() / max(int(frags.inside.sum()), 1))
    fields = anatomy.anatomy_fields(position, normal, frags.face, frags.bary, verts, faces, model.face_labels, skel,
                                    texel_size)
    label = anatomy.texel_labels(model.face_labels[frags.face], fields["nail"], fields["bone"], skel)
    fields.update(noise_bank(position))
    return Bake(
        res=res, texel=frags.pixel, face=frags.face.astype(np.int32), inside=frags.inside,
        position=position.astype(np.float32), normal=normal.astype(np.float32),
        label=label, fields=fields,
        mesh={"vertices": verts, "faces": faces, "face_labels": model.face_labels, "uvs": model.uvs,
              "faces_uv": model.faces_uv, "joints": skel.joints, "tips": skel.tips, "vertex_normals": vnormals},
        key=key)


def noise_bank(position: np.ndarray) -> dict[str, np.ndarray]:
    """The fixed bank of solid-noise fields at `position` (N, 3); (N,) float32 each, rounded to float16 so the
    cache (which stores float16) reproduces them exactly."""
    out = {}
    for band, (count, scale, octaves) in NOISE_BANK.items():
        for k in range(count):
            rng = np.random.default_rng([NOISE_SEED, sum(map(ord, band)), k])
            v = noise.fbm(position, rng, scale, octaves=octaves)
            out[f"noise_{band}{k}"] = v.astype(np.float16).astype(np.float32)
    return out


# ------------------------------------------------------------------------------------------------- cache
def save_bake(b: Bake, path: str | Path) -> None:
    """Write a bake to `path` (uncompressed .npz: it is a cache, read often) atomically."""
    arrays: dict = {"key": np.array(b.key), "res": np.array(b.res), "texel": b.texel, "face": b.face,
                    "inside": b.inside, "position": b.position, "normal": b.normal, "label": b.label}
    arrays.update({f"field_{k}": v.astype(np.float16) if k.startswith("noise_") else v for k, v in b.fields.items()})
    arrays.update({f"mesh_{k}": v for k, v in b.mesh.items()})
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)


def load_bake(path: str | Path) -> Bake:
    """Read a bake written by `save_bake`."""
    with np.load(path, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    fields = {k[6:]: v.astype(np.float32) if v.dtype == np.float16 else v
              for k, v in data.items() if k.startswith("field_")}
    return Bake(res=int(data["res"]), texel=data["texel"], face=data["face"], inside=data["inside"],
                position=data["position"], normal=data["normal"], label=data["label"], fields=fields,
                mesh={k[5:]: v for k, v in data.items() if k.startswith("mesh_")}, key=str(data["key"]))


def cached_bake(model: HandModel, res: int, cache_dir: str | Path | None) -> tuple[Bake, Path | None]:
    """The bake of (model, res), read from `cache_dir/bake_<res>.npz` when its key matches, else baked and
    written there. Returns the bake and the cache path (None without a cache folder)."""
    if cache_dir is None:
        return bake(model, res), None
    path = Path(cache_dir) / f"bake_{int(res)}.npz"
    if path.is_file() and model.has_uvs:
        key = bake_key(prepare_model(model), res)
        try:
            with np.load(path, allow_pickle=False) as z:
                if str(z["key"]) == key:
                    return load_bake(path), path
        except (OSError, ValueError, KeyError):
            pass  # unreadable cache: bake again
    b = bake(model, res)
    save_bake(b, path)
    return b, path
