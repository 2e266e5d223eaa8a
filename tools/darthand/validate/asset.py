"""What the readers extract from a package, in one form for both formats, so that the rule modules (mesh, rig,
textures, accessories) are plain functions of numpy arrays and never see USD or glTF.

Shapes: N points, F triangles, T UVs, k influences per point, J joints. Units metres, hand rest frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Limits:
    """Sizes above which the validator refuses to look at an array (a `file.array-too-large` finding)."""

    max_points: int = 10_000_000
    max_faces: int = 20_000_000
    max_elements: int = 200_000_000      # any other array (weights, offsets, accessor components)
    max_image_pixels: int = 16384 * 16384
    max_json_bytes: int = 256 * 1024 * 1024


@dataclass
class Skin:
    """Joint influences of a mesh's points: indices (N, k) int64 and weights (N, k) float64; `rigid` when one row
    applies to every point (USD constant interpolation); `broken` when they could not be read consistently."""

    indices: np.ndarray
    weights: np.ndarray
    rigid: bool = False
    num_joints: int = 16         # joints of the skeleton the indices refer to
    broken: bool = False         # the reader found the influences inconsistent (already reported)


@dataclass
class BlendShape:
    """One blend shape / morph target: offsets (n, 3); point_indices (n,) into the mesh's points, or None when the
    offsets are dense (one per point)."""

    name: str
    path: str
    offsets: np.ndarray
    point_indices: np.ndarray | None = None


@dataclass
class Mesh:
    """A triangle mesh of the package. role: 'hand', 'cap' (the forearm cap) or 'accessory'.

    points (N, 3) float64 in the hand's rest frame; faces (F, 3) int64 (polygons fan-triangulated); uvs (T, 2) and
    uv_faces (F, 3) per-corner indices into uvs, or None; skin (None: not skinned); blend_shapes;
    claims_correctives: the package says this mesh carries MANO's 135 pose correctives.
    For accessories: accessory_id (catalogue id or None) and rigid_joint (glTF: the joint node it hangs under).
    """

    path: str
    role: str
    points: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray | None = None
    uv_faces: np.ndarray | None = None
    skin: Skin | None = None
    blend_shapes: list[BlendShape] = field(default_factory=list)
    claims_correctives: bool = False
    accessory_id: str | None = None
    rigid_joint: int | None = None
    layout_ok: bool = True       # False when the reader found the arrays inconsistent (rules then skip it)


@dataclass
class Skeleton:
    """Joints in file order: names (J,), parents (J,) (-1 for a root), bind (J, 4, 4) skeleton-space bind
    transforms and rest (J, 4, 4) parent-space rest transforms, both column-vector matrices."""

    path: str
    names: list[str]
    parents: np.ndarray
    bind: np.ndarray
    rest: np.ndarray
    root_parent: np.ndarray | None = None     # (4, 4) transform above the root joint (glTF node parents)


@dataclass
class TextureRef:
    """One texture a material uses.

    asset: the path / URI as authored; file: the file it resolves to (None when embedded or unresolvable);
    data: the bytes of an embedded image (glTF bufferView, data URI, usdz member); role: 'color', 'data' or
    'unknown' (not connected); color_space: the authored colour space (USD sourceColorSpace) or None.
    """

    path: str
    asset: str
    file: Path | None = None
    data: bytes | None = None
    role: str = "unknown"
    color_space: str | None = None
    member: str | None = None         # name inside a usdz archive


@dataclass
class Package:
    """Everything the readers found in one package file. root: the folder (or .usdz) files must stay inside."""

    file: Path
    format: str
    root: Path
    side: str | None = None
    skeletons: list[Skeleton] = field(default_factory=list)
    meshes: list[Mesh] = field(default_factory=list)
    textures: list[TextureRef] = field(default_factory=list)
    texture_ids: list[tuple[str, str]] = field(default_factory=list)      # (id, where it is recorded)
    accessory_ids: list[tuple[str, str]] = field(default_factory=list)

    @property
    def hand_meshes(self) -> list[Mesh]:
        return [m for m in self.meshes if m.role == "hand"]

    @property
    def accessories(self) -> list[Mesh]:
        return [m for m in self.meshes if m.role == "accessory"]
