"""Reading the accessories stage's catalogue (build/accessories/catalog.json): fitted accessories as other stages
use them (export binds them to the skeleton, the renderer poses them). The accessories stage owns how its catalogue
is read; other stages import from here.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import file_in, read_npz
from darthand.model.layout import NUM_JOINTS, NUM_POSE_FEATURES
from darthand.model.mirror import mirror_points, mirror_posedirs
from darthand.schemas import read_catalog


@dataclass(frozen=True)
class Accessory:
    """One accessory's geometry and look, fitted to the rest hand.

    vertices (N, 3) float64, hand rest frame, metres; faces (F, 3); uvs (T, 2) and faces_uv (F, 3) per-corner UVs
    (the model's convention, v up) or None. Exactly one of `parent_joint` (rigid: MANO joint index) and `weights`
    (skinned: (N, 16)) is set; `posedirs` (N, 3, 135) optional correctives of a skinned accessory. material:
    base_color (RGB or RGBA, linear), metallic, roughness; base_color_png / metallic_roughness_png (glTF channel
    layout: G roughness, B metallic): texture files or None. kind: the catalogue's type (ring, watch, bracelet,
    glove). rest_transform (4, 4): a rigid item's local frame in the hand's rest frame (its fit: x along the
    bone, origin on the bore's centre) or None; shapedirs (N, 3, S): a skinned item's shape directions (the hand
    vertices' it follows) or None. Both let accessories/reshape.py refit the item to another hand shape.
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
    rest_transform: np.ndarray | None = None
    shapedirs: np.ndarray | None = None

    @property
    def skinned(self) -> bool:
        return self.weights is not None


def load_accessory_catalog(path: str | Path, ids=None, side: str | None = None) -> list[Accessory]:
    """Accessories from an accessories-stage catalogue (build/accessories/catalog.json, or its folder).

    The file must validate against schemas/accessory_catalog.schema.json. Entry: parent_joint, a joint index
    (rigid) or null (glove); files.npz, files.base_color, files.metallic_roughness relative to the catalogue;
    material {metallic, roughness, base_color (linear RGB, optional), ...}. The npz holds vertices (rest pose, model
    frame), faces, uvs, faces_uv and, for gloves, weights and posedirs. `ids` selects entries (in catalogue order).
    `side`: when the catalogue's model.side is the other hand, every accessory is mirrored (x -> -x).
    """
    path, data = read_catalog(path, "accessory", "accessory_catalog.schema.json")
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
    color = [float(c) for c in m.get("base_color", (0.8, 0.8, 0.8))][:4] + [1.0]
    return (color[0], color[1], color[2], color[3]), float(m.get("metallic", 0.0)), float(m.get("roughness", 0.5))


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
    if acc.rest_transform is not None and acc.rest_transform.shape != (4, 4):
        raise InputError(f"{where}: rest_transform has shape {acc.rest_transform.shape}, expected (4, 4)")
    if acc.shapedirs is not None and (acc.shapedirs.ndim != 3 or acc.shapedirs.shape[:2] != (N, 3)):
        raise InputError(f"{where}: shapedirs have shape {acc.shapedirs.shape}, expected ({N}, 3, S)")


def mirror_accessory(acc: Accessory) -> Accessory:
    """The accessory for the mirror-image hand (x -> -x, winding reversed, correctives and shape directions as in
    mirror_model). A rest frame [R | t] becomes [S R D | S t], S = diag(-1, 1, 1), D = diag(1, 1, -1): the
    mirrored bone frame, still right-handed (x along the bone, y dorsal, z = x cross y)."""
    flip = [0, 2, 1]
    S = np.diag([-1.0, 1.0, 1.0])
    rest = None
    if acc.rest_transform is not None:
        rest = np.eye(4)
        rest[:3, :3] = S @ acc.rest_transform[:3, :3] @ np.diag([1.0, 1.0, -1.0])
        rest[:3, 3] = S @ acc.rest_transform[:3, 3]
    return dataclasses.replace(
        acc, vertices=mirror_points(acc.vertices), faces=acc.faces[:, flip],
        faces_uv=None if acc.faces_uv is None else acc.faces_uv[:, flip],
        posedirs=None if acc.posedirs is None else mirror_posedirs(acc.posedirs), rest_transform=rest,
        shapedirs=None if acc.shapedirs is None else acc.shapedirs * np.array([-1.0, 1.0, 1.0])[None, :, None])


def _entry_accessory(path: Path, entry: dict) -> Accessory:
    files = entry["files"]
    mesh_path = file_in(path.parent, files["npz"], "accessory mesh", must_exist=False)
    arrays = read_npz(mesh_path, "accessory mesh", ("vertices", "faces"))

    def opt(key, dtype):
        return np.asarray(arrays[key], dtype) if key in arrays else None

    acc = Accessory(
        id=entry["id"], vertices=np.asarray(arrays["vertices"], np.float64),
        faces=np.asarray(arrays["faces"], np.int64), uvs=opt("uvs", np.float64), faces_uv=opt("faces_uv", np.int64),
        parent_joint=entry["parent_joint"], weights=opt("weights", np.float64), posedirs=opt("posedirs", np.float64),
        material=dict(entry["material"]), base_color_png=file_in(path.parent, files["base_color"], "texture", False),
        metallic_roughness_png=file_in(path.parent, files["metallic_roughness"], "texture", False), kind=entry["type"],
        rest_transform=opt("rest_transform", np.float64) if entry["parent_joint"] is not None else None,
        shapedirs=opt("shapedirs", np.float64))
    check_accessory(acc, str(path))
    return acc
