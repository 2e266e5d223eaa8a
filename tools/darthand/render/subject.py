"""What one frame renders: posed surfaces (hand, accessory) with their materials, and the hand's 3D keypoints.

Both sources build a `Subject`: the internal path (assets.HandAssets: model npz + catalogue ids, posed by
darthand's forward pass) and the USD path (usd_source.UsdPackage: the package posed by UsdSkel).

Shapes: N vertices, F faces, T UV coordinates; world = the model's frame, metres.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from darthand.render.skin import SKIN_MFP_MM
from darthand.render.texture import MipTexture, checker_texture, constant_texture

SKIN_F0 = 0.028                      # normal-incidence reflectance of skin (refractive index about 1.4)
SKIN_WRAP = (0.32, 0.16, 0.10)       # per-channel wrap: red light reaches furthest past the terminator (scattering)
DIELECTRIC_F0 = 0.04
PLAIN_SKIN = (0.56, 0.36, 0.27)      # linear RGB of the untextured hand (export/usd_materials.SKIN_LINEAR)


@dataclass(frozen=True, eq=False)
class Material:
    """A surface's look.

    kind: 'skin' (wrap diffuse with per-channel `wrap`, dielectric specular `f0`) or 'pbr' (metallic-roughness:
        Lambert diffuse of albedo * (1 - metallic), GGX specular with F0 = mix(f0, albedo, metallic)).
    maps: one texture, channels 0..2 linear albedo, then roughness at `roughness_channel` and metallic at
        `metallic_channel` when they are textured (None: the constants roughness_value / metallic_value).
        Roughness is perceptual (GGX alpha = roughness^2).
    specular: scale of the specular lobe (1 physically based, 0 a purely diffuse surface).
    mfp_mm: skin's mean free path per channel (mm), for the subsurface skin model (skin.py).
    detail: the skin's relief (skin_detail.DetailMap: a bump map built on first use), or None.
    """

    kind: str = "pbr"
    maps: MipTexture = field(default_factory=lambda: constant_texture(PLAIN_SKIN))
    roughness_channel: int | None = None
    roughness_value: float = 0.5
    metallic_channel: int | None = None
    metallic_value: float = 0.0
    wrap: tuple = (0.0, 0.0, 0.0)
    f0: float = DIELECTRIC_F0
    name: str = ""
    specular: float = 1.0
    mfp_mm: tuple = SKIN_MFP_MM
    detail: Any = None


def checker_material() -> Material:
    """The UV checker as an unlit-looking skin (no wrap: the pattern's edges stay where the UVs put them)."""
    return dataclasses.replace(skin_material(checker_texture(), name="checker"), wrap=(0.0, 0.0, 0.0))


def skin_material(maps: MipTexture | None = None, roughness_channel: int | None = None,
                  roughness_value: float = 0.5, name: str = "skin", detail=None) -> Material:
    """The hand's skin: wrap diffuse, skin's specular reflectance, its relief `detail` (or None)."""
    return Material("skin", maps if maps is not None else constant_texture(PLAIN_SKIN), roughness_channel,
                    roughness_value, None, 0.0, SKIN_WRAP, SKIN_F0, name, detail=detail)


@dataclass(frozen=True, eq=False)
class Surface:
    """One posed triangle mesh: vertices (N, 3) float32 world, faces (F, 3) int32, vertex normals (N, 3) float32,
    per-corner uvs (T, 2) float32 + faces_uv (F, 3) int32 (or None), rest-pose vertices (N, 3) (for checks), its
    material, `role` 'hand', 'accessory' or 'cap' (the forearm cap), and face_joints (F,) the joint that moves each
    face most (skinned surfaces; None for rigid ones), for keypoint visibility; face_labels (F,) int8 the model's
    surface labels (model.layout.FACE_LABELS, -1 unlabelled) or None: the skin model leaves nails out. A rigid surface
    also carries `local` (N, 3) float32, its vertices in its joint's frame (the same array every frame, so its
    ray-tracing structure is built once), and
    `transform` (4, 4) float64, the rigid transform G with vertices = G @ [local, 1]."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    material: Material
    uvs: np.ndarray | None = None
    faces_uv: np.ndarray | None = None
    rest: np.ndarray | None = None
    role: str = "hand"
    face_joints: np.ndarray | None = None
    local: np.ndarray | None = None
    transform: np.ndarray | None = None
    face_labels: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class Subject:
    """A posed hand (and accessory) for one frame.

    joints (16, 3) and keypoints (21, 3): world, metres, float64; keypoints in `keypoint_order`. pose (48,): MANO
    axis-angle relative to the flat hand. info: ids for the labels (texture, skin_tone_offset, accessory, gesture,
    source...). The drawn surfaces may differ from the model's (render/dress.py): mesh (N, 3) float32 is then the
    model's own posed hand vertices (None: the hand surface's); framing (M, 3) the points the camera is framed on
    (the plain subject's, so an arm reaching out of the frame or a subdivided skin leaves the camera as it was;
    None: all drawn vertices); labelled the subject whose surfaces the labels' visibility rays are traced against
    (the unsubdivided one, so the labels are the plain frame's; None: this one). members: for a frame of several
    hands (render/bodies.py), each hand's own placed Subject in the scene's bodies order; its surfaces are theirs
    concatenated in that order, and its one-hand fields (joints, keypoints, side, pose) the first's. () for one hand.
    objects: the held objects of such a frame (render/objects.HeldObject), their surfaces after the members'.
    """

    surfaces: tuple
    joints: np.ndarray
    keypoints: np.ndarray
    side: str
    pose: np.ndarray
    keypoint_order: str = "openpose"
    info: dict = field(default_factory=dict)
    mesh: np.ndarray | None = None
    framing: np.ndarray | None = None
    labelled: Subject | None = None
    members: tuple = ()
    objects: tuple = ()

    @property
    def hand(self) -> Surface:
        return next(s for s in self.surfaces if s.role == "hand")

    @property
    def hand_vertices(self) -> np.ndarray:
        """(N, 3) the model's own posed hand vertices (labels and meshes are of these, whatever is drawn)."""
        return self.hand.vertices if self.mesh is None else self.mesh

    def framing_points(self) -> np.ndarray:
        """The points the camera frames (see `framing`)."""
        return self.all_vertices() if self.framing is None else self.framing

    @property
    def accessory(self) -> Surface | None:
        return next((s for s in self.surfaces if s.role == "accessory"), None)

    def all_vertices(self) -> np.ndarray:
        return np.concatenate([s.vertices for s in self.surfaces])
