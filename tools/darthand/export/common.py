"""What the USD and glTF writers share: pruned skin influences, the exported pose correctives and what they cost,
the gestures that become the animation, per-corner UV splitting, texture files, and the texture and accessory
catalogues they read.

Shapes: V vertices, J = 16 joints, K exported corrective directions, G gestures.

Export options (`parse_influences`, `parse_correctives`):
    influences   4 | 8 | all      joints per vertex, strongest first, renormalised to sum 1
    correctives  full | pca:K | pose-pca:K | none
        full   the model's 135 pose correctives, blend-shape weights = pose feature f = flatten(R_i - I)
        pca:K  K directions of the SVD of the corrective matrix A = posedirs arranged (3V, 135), A = U S W^T:
               shapes B = U_K S_K (3V, K), weights c = W_K^T f (K,), so the exported offset B c = U_K U_K^T A f is
               the best rank-K approximation of A in the Frobenius norm. It treats every pose-feature direction
               alike, although hands use few of them.
        pose-pca:K  the same with the pose-feature directions weighted by how poses use them: with
               C = E[f f^T] over POSE_PCA_SAMPLES anatomical poses (`anatomy.sample_poses`, seed POSE_PCA_SEED)
               and C = L L^T, the SVD A L = U S W^T gives shapes B = U_K (3V, K) and weights c = U_K^T A f, the
               rank-K projection minimising the mean squared offset error over that pose distribution
               (about 10x smaller max error than pca:K at K = 32 on the open hand; see the export benchmark)
        none   no correctives: plain skinning of the rest template

UV convention: the model's UVs (`HandModel.uvs`) are OpenGL / OBJ / USD `st` style, v up: (0, 0) is the
bottom-left corner of the image and the texel in row r (row 0 at the top of the file), column c of a W x H image
has its centre at (u, v) = ((c + 0.5) / W, 1 - (r + 0.5) / H). The textures stage bakes with it
(model/atlas.py, textures/bake.py), USD writes it unchanged as `st`, glTF (origin top-left) stores (u, 1 - v).
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import atomic_path, file_in, open_regular, read_json
from darthand.model.forward import forward, pose_feature
from darthand.model.hand_model import HandModel
from darthand.model.layout import NUM_JOINTS, NUM_POSE_FEATURES
from darthand.model.rotations import axis_angle_to_matrix, matrix_to_quaternion
from darthand.schemas import check_schema

INFLUENCE_CHOICES = ("4", "8", "all")  # the --influences values the CLI offers
POSE_PCA_SAMPLES = 4096
POSE_PCA_SEED = 2022
REST_GESTURE = "flat"
# The hand's look without a texture (both writers and the renderer): a mid skin tone, linear RGB, and its roughness
# (also that of a skin texture variant without a roughness map).
SKIN_COLOR = (0.56, 0.36, 0.27)
SKIN_ROUGHNESS = 0.5


# ------------------------------------------------------------------------------------------------ skin weights


def top_k_influences(weights: np.ndarray, k: int | None) -> tuple[np.ndarray, np.ndarray]:
    """The k strongest joints of every vertex: indices (V, k) int32 and weights (V, k) float64.

    Per vertex the weights are sorted descending (ties keep joint order), the rest dropped, and the kept ones
    renormalised to sum 1. Slots without influence (weight 0, also when k > J) get joint index 0, as glTF asks.
    k = None keeps all J joints.
    """
    w = np.asarray(weights, dtype=np.float64)
    V, J = w.shape
    k = J if k is None else int(k)
    if k < 1:
        raise InputError(f"influences: must be at least 1, got {k}")
    order = np.argsort(-w, axis=1, kind="stable")[:, :min(k, J)]
    kept = np.take_along_axis(w, order, axis=1)
    total = kept.sum(axis=1, keepdims=True)
    kept = np.divide(kept, total, out=np.zeros_like(kept), where=total > 0)
    idx = np.where(kept > 0, order, 0).astype(np.int32)
    if k > J:
        kept = np.concatenate([kept, np.zeros((V, k - J))], axis=1)
        idx = np.concatenate([idx, np.zeros((V, k - J), np.int32)], axis=1)
    return idx, kept


def influences_needed(weights: np.ndarray) -> int:
    """The most non-zero weights any vertex has (at least 1): storing that many influences loses nothing."""
    return max(1, int((np.asarray(weights) > 0).sum(axis=1).max(initial=0)))


def dense_weights(indices: np.ndarray, weights: np.ndarray, num_joints: int = NUM_JOINTS) -> np.ndarray:
    """(V, J) dense skin weights from per-vertex (indices, weights) (V, k): the inverse of `top_k_influences`."""
    V = indices.shape[0]
    dense = np.zeros((V, num_joints))
    np.add.at(dense, (np.repeat(np.arange(V), indices.shape[1]), indices.reshape(-1)), weights.reshape(-1))
    return dense


def pruned_model(model: HandModel, k: int | None) -> HandModel:
    """`model` with its skin weights pruned to k influences per vertex (what an exported asset skins with)."""
    if k is None or k >= model.weights.shape[1]:
        return model
    idx, w = top_k_influences(model.weights, k)
    return model.replace(weights=dense_weights(idx, w, model.weights.shape[1]))


def parse_influences(text: str | int | None) -> int | None:
    """'4' -> 4, '8' -> 8, 'all' / None -> None (every joint); anything else is an InputError."""
    if text is None or str(text) == "all":
        return None
    try:
        k = int(text)
    except ValueError:
        raise InputError(f"--influences: {text!r} is not a number or 'all'") from None
    if not 1 <= k <= NUM_JOINTS:
        raise InputError(f"--influences: {k} is outside 1..{NUM_JOINTS} (or 'all')")
    return k


# ------------------------------------------------------------------------------------------------ skeleton


def local_translations(joints: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """(16, 3) each joint's offset from its parent (the root's from the origin): the rest translation of a joint
    node / UsdSkel joint whose frame is world-aligned at rest."""
    rel = np.array(joints, dtype=np.float64)
    rel[1:] -= rel[np.asarray(parents)[1:]]
    return rel


def xyzw_quaternions(rotations: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (x, y, z, w) of rotation matrices (..., 3, 3): the layout of glTF rotations and of
    GfQuatf in memory (rotations.py's are w, x, y, z)."""
    q = matrix_to_quaternion(np.asarray(rotations, dtype=np.float64))
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


# ------------------------------------------------------------------------------------------------ correctives


@dataclass(frozen=True)
class Correctives:
    """The pose correctives an asset carries.

    offsets: (V, 3, K) float64, one blend shape per column (metres).
    projection: (K, 135) float64 or None; blend-shape weights = projection @ pose feature (None: the identity, the
        weights ARE the pose feature, K = 135).
    mode: 'full', 'pca:K', 'pose-pca:K' or 'none'; names: K shape names, valid identifiers.
    """

    mode: str
    offsets: np.ndarray
    projection: np.ndarray | None
    names: tuple[str, ...]

    @property
    def count(self) -> int:
        return int(self.offsets.shape[2])

    def weights(self, rotations: np.ndarray) -> np.ndarray:
        """(B, K) blend-shape weights of poses with local rotations (B, 16, 3, 3)."""
        f = pose_feature(np.asarray(rotations, dtype=np.float64))
        return f if self.projection is None else f @ self.projection.T

    def weights_of_poses(self, poses: np.ndarray) -> np.ndarray:
        """(B, K) blend-shape weights of axis-angle poses (B, 48)."""
        aa = np.asarray(poses, dtype=np.float64).reshape(-1, NUM_JOINTS, 3)
        return self.weights(axis_angle_to_matrix(aa))


def corrective_names() -> tuple[str, ...]:
    """The 135 pose-corrective names `pose_jJJ_rRC`: joint 1..15, entry (r, c) of R_j - I."""
    return tuple(f"pose_j{j:02d}_r{r}{c}" for j in range(1, NUM_JOINTS) for r in range(3) for c in range(3))


def parse_correctives(text: str) -> tuple[str, int | None]:
    """'full' -> ('full', None), 'none' -> ('none', None), 'pca:K' -> ('pca', K), 'pose-pca:K' -> ('pose-pca', K)."""
    text = str(text)
    if text in ("full", "none"):
        return text, None
    kind, _, k = text.partition(":")
    if kind in ("pca", "pose-pca") and k.isdigit() and 1 <= int(k) <= NUM_POSE_FEATURES:
        return kind, int(k)
    raise InputError(f"--correctives: {text!r} is not 'full', 'none', 'pca:K' or 'pose-pca:K' with K in "
                     f"1..{NUM_POSE_FEATURES}")


def check_export_options(influences: int | None, correctives: str, texture_size: int | None) -> None:
    """InputError naming the option when the influences (1..16 or None), correctives (`parse_correctives`) or
    texture size (pixels, positive or None) an export was asked for are invalid."""
    if influences is not None and not 1 <= influences <= NUM_JOINTS:
        raise InputError(f"--influences: {influences} is outside 1..{NUM_JOINTS} (or 'all')")
    parse_correctives(correctives)
    if texture_size is not None and texture_size < 1:
        raise InputError(f"--texture-size: must be a positive number of pixels, got {texture_size}")


def export_correctives(model: HandModel, mode: str = "full") -> Correctives:
    """The correctives to export for `mode` ('full' | 'pca:K' | 'pose-pca:K' | 'none'); see the module docstring."""
    kind, k = parse_correctives(mode)
    V = model.num_vertices
    if kind == "full":
        return Correctives("full", model.posedirs, None, corrective_names())
    if kind == "none":
        return Correctives("none", np.zeros((V, 3, 0)), np.zeros((0, NUM_POSE_FEATURES)), ())
    A = model.posedirs.reshape(3 * V, NUM_POSE_FEATURES)
    names = tuple(f"pose_pca{i:03d}" for i in range(k))
    if kind == "pca":
        U, S, Wt = np.linalg.svd(A, full_matrices=False)
        return Correctives(f"pca:{k}", (U[:, :k] * S[:k]).reshape(V, 3, k), Wt[:k].copy(), names)
    U = np.linalg.svd(A @ pose_feature_sqrt_covariance(model), full_matrices=False)[0][:, :k]
    return Correctives(f"pose-pca:{k}", U.reshape(V, 3, k), U.T @ A, names)


def pose_feature_sqrt_covariance(model: HandModel) -> np.ndarray:
    """(135, 135) L with L L^T = E[f f^T], the second moment of the pose feature over POSE_PCA_SAMPLES anatomical
    poses of `model` (seeded, so the export is deterministic); a tiny ridge keeps the Cholesky factor defined."""
    from darthand.model.anatomy import sample_poses

    poses = sample_poses(model, POSE_PCA_SAMPLES, np.random.default_rng(POSE_PCA_SEED))
    f = pose_feature(axis_angle_to_matrix(poses.reshape(-1, NUM_JOINTS, 3)))
    C = f.T @ f / len(f)
    return np.linalg.cholesky(C + 1e-12 * np.trace(C) * np.eye(NUM_POSE_FEATURES))


def exported_model(model: HandModel, correctives: Correctives, influences: int | None = None) -> HandModel:
    """The rig an exported asset carries: `model` with its correctives replaced by the exported ones (offsets @
    projection, (V, 3, 135)) and its skin weights pruned to `influences`. `forward` on it is what a consumer of
    the asset computes, so comparing it with `forward` on `model` measures the export options' error."""
    if correctives.projection is None:
        posedirs = correctives.offsets
    elif correctives.count == 0:
        posedirs = np.zeros_like(model.posedirs)
    else:
        posedirs = correctives.offsets @ correctives.projection
    return pruned_model(model.replace(posedirs=posedirs), influences)


# ------------------------------------------------------------------------------------------------ option errors


def corrective_error(model: HandModel, correctives: Correctives, poses: np.ndarray) -> np.ndarray:
    """(B,) max over vertices of |exported corrective offset - model's corrective offset| (metres) for poses (B, 48).

    Skinning is linear in the rest-frame offset and rigid per joint, so this bounds the posed-vertex error the
    corrective approximation alone adds (skinning weights that sum to 1 do not lengthen an offset); `option_errors`
    measures the posed error itself.
    """
    rot = axis_angle_to_matrix(np.asarray(poses, dtype=np.float64).reshape(-1, NUM_JOINTS, 3))
    f = pose_feature(rot)
    V = model.num_vertices
    exact = f @ model.posedirs.reshape(3 * V, -1).T
    approx = correctives.weights(rot) @ correctives.offsets.reshape(3 * V, -1).T if correctives.count else 0.0
    diff = (exact - approx).reshape(len(f), V, 3)
    return np.linalg.norm(diff, axis=2).max(axis=1)


def rig_error(model: HandModel, rig: HandModel, poses: np.ndarray, truth: np.ndarray | None = None) -> float:
    """Max vertex distance (metres) between `forward` on `model` (or its precomputed vertices `truth` (B, V, 3))
    and `forward` on `rig` over poses (B, 48); 0 for no poses."""
    if not len(poses):
        return 0.0
    truth = forward(model, poses).vertices if truth is None else truth
    return float(np.linalg.norm(forward(rig, poses).vertices - truth, axis=-1).max())


def option_errors(model: HandModel, correctives: Correctives, influences: int | None, poses: np.ndarray,
                  truth: np.ndarray | None = None) -> dict:
    """What each export option costs over poses (B, 48), as posed max vertex errors (metres) against the model:
    `influence_error_m` of the pruned skin weights (with the model's correctives), `corrective_error_m` of the
    exported correctives (with the full weights)."""
    if len(poses) and truth is None:
        truth = forward(model, poses).vertices
    return {"influence_error_m": rig_error(model, pruned_model(model, influences), poses, truth),
            "corrective_error_m": rig_error(model, exported_model(model, correctives), poses, truth)}


# ------------------------------------------------------------------------------------------------ gestures


def gesture_poses(model: HandModel) -> tuple[list[str], np.ndarray]:
    """Names and MANO axis-angle poses (G, 48) of the named gestures (assets_src/poses/*.json) for `model`.

    Sorted by name except that `flat` (the rest pose) comes first, so that an animation's first frame is the rest
    pose. Without any gesture the animation holds only the rest pose: (['rest'], zeros (1, 48)).
    """
    from darthand.model.poses import gesture_poses as named_gestures

    names, poses = named_gestures(model)
    if not names:
        return ["rest"], np.zeros((1, 3 * NUM_JOINTS))
    order = sorted(range(len(names)), key=lambda i: (names[i] != REST_GESTURE, names[i]))
    return [names[i] for i in order], np.asarray(poses, dtype=np.float64)[order]


# ------------------------------------------------------------------------------------------------ UV seams


def split_uv_vertices(faces: np.ndarray, faces_uv: np.ndarray | None = None,
                      uvs: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Per-vertex UVs for formats without per-corner attributes (glTF): vertices on a UV seam are duplicated.

    faces (F, 3), faces_uv (F, 3) per-corner indices into uvs (T, 2), or both None. Returns source (N,) int64, the
    input vertex each output vertex copies (positions, weights, correctives are gathered through it); uvs (N, 2)
    or None; faces (F, 3) int64 into the N output vertices. Output vertices are the distinct (vertex, uv index)
    corner pairs (without UVs: the vertices the faces use), ordered by vertex then uv index, so a mesh without
    seams or unused vertices keeps its vertex order. Vertices no face uses are dropped.
    """
    faces = np.asarray(faces, dtype=np.int64)
    if uvs is None:
        source, inverse = np.unique(faces, return_inverse=True)
        return source, None, inverse.reshape(faces.shape)
    pairs = np.stack([faces.reshape(-1), np.asarray(faces_uv, dtype=np.int64).reshape(-1)], axis=1)
    unique, inverse = np.unique(pairs, axis=0, return_inverse=True)
    return unique[:, 0].copy(), np.asarray(uvs)[unique[:, 1]], inverse.reshape(faces.shape)


# ------------------------------------------------------------------------------------------------ texture files


def place_texture(src: str | os.PathLike, dst: str | os.PathLike, size: int | None = None,
                  srgb: bool = True) -> None:
    """Put the image `src` at `dst` in a package, atomically: a hard link (a copy across file systems) when it
    needs no resizing, else the image downsized by `texture_bytes`' rule."""
    src = _texture_file(src)
    image = _downsized(src, size, srgb)
    with atomic_path(dst) as tmp:
        if image is None:
            tmp.unlink()
            try:
                os.link(src, tmp)
            except OSError:
                shutil.copyfile(src, tmp)
        else:
            _write_image(image, tmp, src)


def texture_bytes(src: str | os.PathLike, size: int | None = None, srgb: bool = True) -> bytes:
    """The file bytes of image `src`, downsized so that its longer side is at most `size` pixels (never upsized,
    aspect kept, the source's pixel format kept). Colour images (`srgb`) are resized in linear light (sRGB ->
    linear -> resize -> sRGB), since averaging sRGB values darkens edges; data maps as stored."""
    src = _texture_file(src)
    image = _downsized(src, size, srgb)
    if image is None:
        return src.read_bytes()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / f"resized{src.suffix}"
        _write_image(image, out, src)
        return out.read_bytes()


def _texture_file(src: str | os.PathLike) -> Path:
    src = Path(src)
    if not src.is_file():
        raise InputError(f"{src}: texture file not found")
    return src


def _downsized(src: Path, size: int | None, srgb: bool):
    """An OpenImageIO buffer of `src` downsized to `size` (longer side), or None when it is small enough."""
    if size is None:
        return None
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(str(src))
    spec = buf.spec()
    if buf.has_error or spec.width == 0:
        raise InputError(f"{src}: cannot read image ({buf.geterror()})")
    if max(spec.width, spec.height) <= size:
        return None
    scale = size / max(spec.width, spec.height)
    w, h = max(1, round(spec.width * scale)), max(1, round(spec.height * scale))
    if srgb:
        buf = oiio.ImageBufAlgo.colorconvert(buf, "sRGB", "linear")
    buf = oiio.ImageBufAlgo.resize(buf, roi=oiio.ROI(0, w, 0, h, 0, 1, 0, spec.nchannels))
    if srgb:
        buf = oiio.ImageBufAlgo.colorconvert(buf, "linear", "sRGB")
    buf.set_write_format(spec.format)
    return buf


def _write_image(buf, path: Path, src: Path) -> None:
    if not buf.write(str(path)):
        raise InputError(f"{src}: could not write the resized image ({buf.geterror()})")


# ------------------------------------------------------------------------------------------------ catalogues


@dataclass(frozen=True)
class TextureSet:
    """One skin texture variant: `id` (the variant name), an sRGB albedo PNG and an optional raw roughness PNG."""

    id: str
    albedo: Path
    roughness: Path | None = None


@dataclass(frozen=True)
class Accessory:
    """One accessory's geometry and look, fitted to the rest hand.

    vertices (N, 3) float64, hand rest frame, metres; faces (F, 3); uvs (T, 2) and faces_uv (F, 3) per-corner UVs
    (the model's convention, v up) or None. Exactly one of `parent_joint` (rigid: MANO joint index) and `weights`
    (skinned: (N, 16)) is set; `posedirs` (N, 3, 135) optional correctives of a skinned accessory. material:
    base_color (RGB or RGBA, linear), metallic, roughness; base_color_png / metallic_roughness_png (glTF channel
    layout: G roughness, B metallic): texture files or None. kind: the catalogue's type (ring, watch, bracelet,
    glove).
    """

    id: str
    vertices: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray | None = None
    faces_uv: np.ndarray | None = None
    parent_joint: int | None = None
    weights: np.ndarray | None = None
    posedirs: np.ndarray | None = None
    material: dict = field(default_factory=dict)
    base_color_png: Path | None = None
    metallic_roughness_png: Path | None = None
    kind: str = ""

    @property
    def skinned(self) -> bool:
        return self.weights is not None


def load_texture_catalog(path: str | Path) -> list[TextureSet]:
    """The skin texture variants of a textures-stage catalogue (build/textures/catalog.json, or its folder), the
    default variant first (the catalogue's 'default' when it names an entry, else its first entry), then the others
    in catalogue order.

    The file must validate against schemas/texture_catalog.schema.json (InputError naming the field otherwise).
    Each entry's files.albedo (sRGB PNG) and files.roughness (raw PNG or null) are relative to the catalogue.
    """
    path = _catalog_file(path)
    data = _read_catalog(path, "texture", "texture_catalog.schema.json")
    if not data["entries"]:
        raise InputError(f"{path}: field 'entries' is empty (build textures with the textures stage)")
    entries = sorted(data["entries"], key=lambda e: e["id"] != data.get("default"))     # stable: default first
    return [TextureSet(e["id"], file_in(path.parent, e["files"]["albedo"], "texture", must_exist=False),
                       file_in(path.parent, e["files"]["roughness"], "texture", must_exist=False)
                       if e["files"]["roughness"] else None)
            for e in entries]


def check_textures_fit(model: HandModel, textures: list[TextureSet]) -> None:
    """InputError when skin textures are asked for a model without UVs (they could not be mapped)."""
    if textures and not model.has_uvs:
        raise InputError(f"{model.meta.get('source', 'model')}: the model has no UVs, so the skin textures cannot "
                         "be mapped (darthand.model.atlas.ensure_uvs makes the atlas they were baked for)")


def select_textures(sets: list[TextureSet], ids) -> list[TextureSet]:
    """The sets with the given ids, in that order (InputError naming an unknown id)."""
    by_id = {t.id: t for t in sets}
    missing = [i for i in ids if i not in by_id]
    if missing:
        raise InputError(f"--texture: {missing[0]!r} is not in the texture catalogue")
    return [by_id[i] for i in ids]


def load_accessory_catalog(path: str | Path, ids=None, side: str | None = None) -> list[Accessory]:
    """Accessories from an accessories-stage catalogue (build/accessories/catalog.json, or its folder).

    The file must validate against schemas/accessory_catalog.schema.json. Entry: parent_joint, a joint index
    (rigid) or null (glove); files.npz, files.base_color, files.metallic_roughness relative to the catalogue;
    material {metallic, roughness, base_color (linear RGB, optional), ...}. The npz holds vertices (rest pose, model
    frame), faces, uvs, faces_uv and, for gloves, weights and posedirs. `ids` selects entries (in catalogue order).
    `side`: when the catalogue's model.side is the other hand, every accessory is mirrored (x -> -x).
    """
    path = _catalog_file(path)
    data = _read_catalog(path, "accessory", "accessory_catalog.schema.json")
    wanted = None if ids is None else list(ids)
    mirror = side is not None and side != data["model"]["side"]
    out = []
    for entry in data["accessories"]:
        if wanted is None or entry["id"] in wanted:
            acc = _entry_accessory(path, entry)
            out.append(mirror_accessory(acc) if mirror else acc)
    if wanted is not None:
        missing = sorted(set(wanted) - {a.id for a in out})
        if missing:
            raise InputError(f"{path}: no accessory with id {missing[0]!r}")
    return out


def accessory_factors(acc: Accessory) -> tuple[tuple[float, float, float, float], float, float]:
    """The constant look of an accessory's material: base colour (linear RGBA), metallic, roughness, from its
    catalogue material (defaults: light grey, 0, 0.5). Writers use them where the accessory has no texture."""
    m = acc.material
    color = [float(c) for c in m.get("base_color", (0.8, 0.8, 0.8))][:4]
    return tuple(color + [1.0] * (4 - len(color))), float(m.get("metallic", 0.0)), float(m.get("roughness", 0.5))


def check_accessory(acc: Accessory, source: str = "accessory") -> None:
    """InputError naming the accessory and field when its arrays are inconsistent."""
    where = f"{source}: accessory {acc.id!r}"
    N = len(acc.vertices)
    if acc.vertices.ndim != 2 or acc.vertices.shape[1] != 3 or acc.faces.ndim != 2 or acc.faces.shape[1] != 3:
        raise InputError(f"{where}: vertices and faces must be (N, 3) and (F, 3)")
    if acc.faces.size and (acc.faces.min() < 0 or acc.faces.max() >= N):
        raise InputError(f"{where}: faces index a vertex outside 0..{N - 1}")
    if (acc.parent_joint is None) == (acc.weights is None):
        raise InputError(f"{where}: give exactly one of parent_joint (rigid) and weights (skinned)")
    if acc.parent_joint is not None and not 0 <= acc.parent_joint < NUM_JOINTS:
        raise InputError(f"{where}: parent_joint {acc.parent_joint} is outside 0..{NUM_JOINTS - 1}")
    if acc.weights is not None and acc.weights.shape != (N, NUM_JOINTS):
        raise InputError(f"{where}: weights have shape {acc.weights.shape}, expected ({N}, {NUM_JOINTS})")
    if acc.posedirs is not None and acc.posedirs.shape != (N, 3, NUM_POSE_FEATURES):
        raise InputError(f"{where}: posedirs have shape {acc.posedirs.shape}, expected ({N}, 3, 135)")
    if (acc.uvs is None) != (acc.faces_uv is None):
        raise InputError(f"{where}: uvs and faces_uv must be given together")
    if acc.faces_uv is not None and acc.faces_uv.shape != acc.faces.shape:
        raise InputError(f"{where}: faces_uv has shape {acc.faces_uv.shape}, expected {acc.faces.shape}")


def mirror_accessory(acc: Accessory) -> Accessory:
    """The accessory for the mirror-image hand (x -> -x, winding reversed, correctives as in mirror_model)."""
    from darthand.model.mirror import _FEATURE_SIGN, _S

    flip = [0, 2, 1]
    return dataclasses.replace(
        acc, vertices=acc.vertices * _S, faces=acc.faces[:, flip],
        faces_uv=None if acc.faces_uv is None else acc.faces_uv[:, flip],
        posedirs=None if acc.posedirs is None else acc.posedirs * _S[None, :, None] * _FEATURE_SIGN[None, None, :])


def accessory_offsets(acc: Accessory, correctives: Correctives) -> np.ndarray:
    """(N, 3, K) blend shapes of a skinned accessory driven by the hand's blend-shape weights c = P f.

    Its own correctives G (N, 3, 135) are mapped through the pseudo-inverse of the projection, D = G P^+ (G itself
    for full, G W_K^T for pca:K whose P = W_K has orthonormal rows; the least-squares fit for pose-pca:K), so
    D c = G P^+ P f is G f restricted to the pose directions the hand's weights carry. (N, 3, 0) without
    correctives.
    """
    N, K = len(acc.vertices), correctives.count
    if acc.posedirs is None or K == 0:
        return np.zeros((N, 3, 0))
    if correctives.projection is None:
        return acc.posedirs
    return acc.posedirs @ np.linalg.pinv(correctives.projection)


def _catalog_file(path: str | Path) -> Path:
    """A catalogue file, given itself or its folder."""
    path = Path(path)
    return path / "catalog.json" if path.is_dir() else path


def _read_catalog(path: Path, what: str, schema: str) -> dict:
    """The catalogue at `path`, checked against schemas/<schema>; InputError naming the file and field."""
    data = read_json(path, f"{what} catalogue (build it with the {what} stage)")
    check_schema(data, schema, str(path))
    return data


def _entry_accessory(path: Path, entry: dict) -> Accessory:
    files = entry["files"]
    mesh_path = file_in(path.parent, files["npz"], "accessory mesh", must_exist=False)
    try:
        with open_regular(mesh_path, "accessory mesh") as f, np.load(f, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except InputError as e:
        raise InputError(f"{mesh_path}: unreadable accessory mesh ({str(e).split(': ', 1)[-1]})") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise InputError(f"{mesh_path}: unreadable accessory mesh ({e})") from None
    for key in ("vertices", "faces"):
        if key not in arrays:
            raise InputError(f"{mesh_path}: field '{key}' is missing")

    def opt(key, dtype):
        return np.asarray(arrays[key], dtype) if key in arrays else None

    acc = Accessory(
        id=entry["id"], vertices=np.asarray(arrays["vertices"], np.float64),
        faces=np.asarray(arrays["faces"], np.int64), uvs=opt("uvs", np.float64), faces_uv=opt("faces_uv", np.int64),
        parent_joint=entry["parent_joint"], weights=opt("weights", np.float64), posedirs=opt("posedirs", np.float64),
        material=dict(entry["material"]), base_color_png=file_in(path.parent, files["base_color"], "texture", False),
        metallic_roughness_png=file_in(path.parent, files["metallic_roughness"], "texture", False), kind=entry["type"])
    check_accessory(acc, str(path))
    return acc
