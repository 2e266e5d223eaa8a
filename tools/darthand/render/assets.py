"""The internal (fast) source of frames: a model npz plus the texture and accessory catalogues, posed by darthand's
forward pass.

Per frame only what moved is recomputed: the hand's vertices and normals when the pose changes; a rigid accessory is
its fixed rest mesh moved by its joint's transform (its rest normals are computed once); a glove is skinned like the
hand. Given betas (a dataset's shape per frame), the hand is that shape and an accessory is refitted to it
(accessories/reshape.py: ring bores, watch and bracelet sizes, glove surfaces), its arrays kept per shape while the
shape stays. Textures are decoded once per file pair; a skin-tone offset is a decode table on the shared pyramid
(texture.load_maps).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from darthand.accessories.attach import pose_skinned
from darthand.accessories.loader import Accessory, load_accessory_catalog
from darthand.accessories.reshape import ShapeRefitter
from darthand.accessories.wear import wear_ring
from darthand.errors import InputError
from darthand.model.cap import forearm_cap
from darthand.model.forward import forward
from darthand.model.gestures import model_gestures
from darthand.model.hand_model import HandModel
from darthand.model.layout import NUM_POSE_FEATURES
from darthand.model.load import load_model
from darthand.model.topology import face_joints, vertex_normals
from darthand.render.arm import ARM, ARM_END, check_length, forearm_arm
from darthand.render.poses import resolve_pose
from darthand.render.skin_detail import DetailMap
from darthand.render.subject import PLAIN_SKIN, Material, Subject, Surface, checker_material, skin_material
from darthand.render.texture import constant_texture, load_maps
from darthand.textures.color import linear_to_srgb, srgb_to_linear
from darthand.textures.loader import TextureSet, load_texture_catalog

PLAIN = "plain"        # texture id of the untextured hand (a constant skin colour)
CHECKER = "checker"    # texture id of the UV checker
NONE = "none"          # accessory id of no accessory


@dataclass(eq=False)
class HandAssets:
    """A model (wrist-enhanced, with UVs) and its catalogues (ids -> TextureSet / Accessory): a `FrameSource`
    (render/source.py) of kind 'model', posed by darthand's forward pass."""

    kind: ClassVar[str] = "model"

    model: HandModel
    textures: dict = field(default_factory=dict)
    default_texture: str | None = None
    accessories: dict = field(default_factory=dict)
    source: str = "model"
    _rest_normals: dict = field(default_factory=dict, repr=False)
    _last: tuple | None = field(default=None, repr=False)
    _last_accessory: tuple | None = field(default=None, repr=False)
    _gestures: dict = field(default_factory=dict, repr=False)
    _face_joints: dict = field(default_factory=dict, repr=False)    # also float32 glove arrays, ("f32", id)
    _refitter: Any = field(default=None, repr=False)          # accessories.reshape.ShapeRefitter, made once
    _refits: tuple | None = field(default=None, repr=False)       # (shape key, {id: refitted Accessory})
    worn_rings: bool = False     # rings worn per pose (accessories/wear), as dataset frames show them
    _detail: Any = field(default=None, repr=False)            # skin_detail.DetailMap of the model, made once

    @classmethod
    def load(cls, model, textures=None, accessories=None) -> "HandAssets":
        """From a model (HandModel or a path/name for model.load.load_model) and catalogue paths (file or folder;
        None: none). Accessories fitted to the other hand are mirrored."""
        m = model if isinstance(model, HandModel) else load_model(model)
        sets, default = texture_catalog(textures) if textures else ([], None)
        accs = load_accessory_catalog(accessories, side=m.side) if accessories else []
        return cls(m, {t.id: t for t in sets}, default, {a.id: a for a in accs},
                   str(model) if not isinstance(model, HandModel) else m.meta.get("source", "model"))

    # ---------------------------------------------------------------------------------------------- ids

    @property
    def side(self) -> str:
        return self.model.side

    def relabel(self, name: str) -> None:
        self.source = name

    def pose_model(self) -> HandModel:
        return self.model

    def gesture_names(self) -> list[str]:
        return list(model_gestures(self.model).names)

    def accessory_type(self, accessory_id: str) -> str | None:
        acc = self.accessories.get(accessory_id)
        return acc.kind if acc is not None else None

    def describe(self) -> dict:
        """What a dataset's writers need of the model without opening it: hands_mean (45,), betas, vertex counts,
        the file format it was read from ('MANO pickle' for a MANO file: its parameters are MANO's)."""
        model = self.model
        wrist = model.meta.get("wrist") or {}
        return {"source": str(self.source), "format": str(model.meta.get("format", "darthand")),
                "hands_mean": np.asarray(model.hands_mean).tolist(),
                "num_betas": model.num_betas, "vertices": model.num_vertices,
                "base_vertices": int(wrist.get("base_vertices", model.num_vertices))}

    def texture_ids(self) -> list[str]:
        return list(self.textures) + [PLAIN, CHECKER]

    def accessory_ids(self) -> list[str]:
        return [NONE] + list(self.accessories)

    def resolve_texture(self, texture: str | None) -> str:
        texture = texture or self.default_texture or PLAIN
        if texture not in (PLAIN, CHECKER) and texture not in self.textures:
            known = ", ".join(list(self.textures)[:5]) + (" ..." if len(self.textures) > 5 else "")
            raise InputError(f"texture: {texture!r} is not in the texture catalogue "
                             f"({known or 'no catalogue given'}; or {PLAIN!r}, {CHECKER!r})")
        return texture

    def resolve_accessory(self, accessory: str | None) -> str:
        accessory = accessory or NONE
        if accessory != NONE and accessory not in self.accessories:
            known = ", ".join(list(self.accessories)[:5]) + (" ..." if len(self.accessories) > 5 else "")
            raise InputError(f"accessory: {accessory!r} is not in the accessory catalogue "
                             f"({known or 'no catalogue given'}; or {NONE!r})")
        return accessory

    # ---------------------------------------------------------------------------------------------- posing

    def subject(self, pose=None, *, texture: str | None = None, skin_tone_offset: float = 0.0,
                accessory: str | None = None, betas=None, keypoint_order: str = "openpose",
                arm: float = 0.0) -> Subject:
        """The posed hand (and accessory) for a pose: None (flat), a gesture name, a pose file, or (48,) axis-angle
        relative to the flat hand. arm: metres of forearm drawn past the cut instead of its cap (render/arm.py; 0:
        the cap), the camera still framed on the hand, accessory and cap (Subject.framing)."""
        pose_vec, gesture = resolve_pose(self.model, pose, cache=self._gestures)
        texture, accessory = self.resolve_texture(texture), self.resolve_accessory(accessory)
        worn = None
        if self.worn_rings and accessory != NONE and self.accessories[accessory].kind == "ring":
            pose_vec, worn = wear_ring(self.model, *self.fitted_accessory(accessory, betas), pose_vec, betas)
        key = (pose_vec.tobytes(), None if betas is None else np.asarray(betas, np.float64).tobytes(), keypoint_order)
        if self._last is not None and self._last[0] == key:
            posed, hand_v, hand_n = self._last[1:]
        else:
            # float32: the vertices Embree traces and the keypoints labelled come from the same pass (float32
            # keeps them within a micrometre of float64 on a hand-sized model).
            posed = forward(self.model, pose_vec[None], betas, keypoint_order=keypoint_order, dtype=np.float32)
            hand_v = posed.vertices[0]
            hand_n = vertex_normals(hand_v, self.model.faces)
            self._last = (key, posed, hand_v, hand_n)
        m = self.model
        if "hand" not in self._face_joints:
            self._face_joints["hand"] = face_joints(m.faces, m.weights)
        faces, uvs, faces_uv = self._static_arrays("hand", m)
        hand = Surface("hand", hand_v, faces, hand_n, self.skin(texture, skin_tone_offset), uvs, faces_uv,
                       m.v_template, "hand", self._face_joints["hand"], face_labels=m.face_labels)
        surfaces = [hand]
        if accessory != NONE:
            if self._last_accessory is None or self._last_accessory[0] != (key, accessory):
                acc, acc_key = self.fitted_accessory(accessory, betas)
                move = None if worn is None else worn.move
                self._last_accessory = ((key, accessory), self.posed_accessory(acc, posed, acc_key, move))
            surfaces.append(self._last_accessory[1])
        cap = self.posed_cap(posed, betas, hand.material)
        framing = None
        if arm:
            framing = np.concatenate([s.vertices for s in surfaces] + [cap.vertices])
            surfaces.extend(self.posed_arm(posed, betas, hand.material, arm))
        else:
            surfaces.append(cap)                     # last: surface indices 0 hand, 1 accessory
        info = {"source": self.source, "texture": texture, "skin_tone_offset": float(skin_tone_offset),
                "tone_srgb": self.skin_tone(texture, skin_tone_offset), "accessory": accessory, "gesture": gesture,
                **({} if worn is None else {"ring_worn": worn.record}),
                "accessory_parent_joint": None if accessory == NONE else self.accessories[accessory].parent_joint,
                "base_faces": (m.meta.get("wrist") or {}).get("base_faces")}     # before the wrist rings (truth.py)
        return Subject(tuple(surfaces), posed.joints[0].astype(np.float64), posed.keypoints[0].astype(np.float64),
                       m.side, pose_vec, keypoint_order, info, framing=framing)

    def skin_tone(self, texture: str, offset: float = 0.0) -> list | None:
        """(3,) sRGB the back of the hand's albedo for a texture id and skin-tone offset (the offset added, clipped
        to [0, 1], as the decoding adds it), None for the checker or a texture whose catalogue has no tone."""
        if texture == PLAIN:
            tone = plain_srgb(offset)
        elif texture == CHECKER or self.textures[texture].tone_srgb is None:
            return None
        else:
            tone = np.clip(np.asarray(self.textures[texture].tone_srgb) + offset, 0.0, 1.0)
        return [round(float(c), 6) for c in tone]

    def skin(self, texture: str, offset: float = 0.0) -> Material:
        """The hand's material for a texture id and skin-tone offset (added to the sRGB albedo)."""
        if texture == PLAIN:
            plain = srgb_to_linear(plain_srgb(offset))
            return skin_material(constant_texture(plain), name=PLAIN, detail=self.detail_map())
        if texture == CHECKER:
            return checker_material()
        t: TextureSet = self.textures[texture]
        if not self.model.has_uvs:
            raise InputError(f"{self.source}: the model has no UVs, so texture {texture!r} cannot be mapped")
        maps = load_maps(t.albedo, offset=offset, data=t.roughness, channels=(0,))
        return skin_material(maps, 3 if t.roughness else None, name=texture, detail=self.detail_map())

    def detail_map(self) -> DetailMap | None:
        """The model's skin relief (built when a frame first asks for it), None for a model without UVs."""
        if self._detail is None and self.model.has_uvs:
            self._detail = DetailMap(self.model)
        return self._detail

    def _static_arrays(self, key, mesh) -> tuple:
        """(faces int32, uvs float32 or None, faces_uv int32 or None) of a model or accessory, converted once: the
        same arrays every frame, so that a rigid accessory's cached Embree scene (scene._local_scene, keyed by
        array identity) is found again."""
        arrays = self._rest_normals.get(("static", key))
        if arrays is None:
            arrays = self._rest_normals["static", key] = (
                np.ascontiguousarray(mesh.faces, np.int32),
                None if mesh.uvs is None else np.ascontiguousarray(mesh.uvs, np.float32),
                None if mesh.faces_uv is None else np.ascontiguousarray(mesh.faces_uv, np.int32))
        return arrays

    def posed_cap(self, posed, betas, material: Material) -> Surface:
        """The forearm cap (model/cap.py) for a forward-pass result, in the hand's material."""
        if "cap" not in self._face_joints:
            cap = forearm_cap(self.model)
            self._face_joints["cap"] = (cap, face_joints(cap.faces, cap.weights), *(
                None if a is None else np.ascontiguousarray(a, t) for a, t in
                ((cap.faces, np.int32), (cap.uvs, np.float32), (cap.faces_uv, np.int32))))
        cap, joints, faces, uvs, faces_uv = self._face_joints["cap"]
        v = cap.pose(posed, betas)[0].astype(np.float32)
        return Surface("forearm_cap", v, faces, vertex_normals(v, faces), material, uvs, faces_uv, cap.vertices,
                       "cap", joints)

    def posed_arm(self, posed, betas, material: Material, length: float) -> tuple[Surface, Surface]:
        """(the forearm tube, its far end's cap) of `length` metres (render/arm.py) for a forward-pass result, in the
        hand's material."""
        key = ("arm", check_length(length))
        if key not in self._face_joints:
            arm = forearm_arm(self.model, length)
            sk = arm.skin
            joints = face_joints(sk.faces, sk.weights)
            T, K, L = arm.tube_faces, arm.tube_vertices, arm.ring_size
            i32, f32 = (lambda a: np.ascontiguousarray(a, np.int32)), (lambda a: np.ascontiguousarray(a, np.float32))
            # the rest slices too: the same arrays every frame, so the skin's curvature (render/skin.surface_radius,
            # kept per rest array) is worked out once, not each frame (1.4 ms)
            tube = (i32(sk.faces[:T]), None if sk.uvs is None else f32(sk.uvs),
                    None if sk.faces_uv is None else i32(sk.faces_uv[:T]), joints[:T], sk.vertices[:K])
            end = (i32(sk.faces[T:] - (K - L)), None if sk.uvs is None else f32(sk.uvs),
                   None if sk.faces_uv is None else i32(sk.faces_uv[T:]), joints[T:], sk.vertices[K - L:])
            self._face_joints[key] = (arm, tube, end)
        arm, tube, end = self._face_joints[key]
        v = arm.skin.pose(posed, betas)[0].astype(np.float32)
        K, L = arm.tube_vertices, arm.ring_size
        tube_v, end_v = np.ascontiguousarray(v[:K]), np.ascontiguousarray(v[K - L:])
        return (Surface(ARM, tube_v, tube[0], vertex_normals(tube_v, tube[0]), material, tube[1], tube[2],
                        tube[4], "arm", tube[3]),
                Surface(ARM_END, end_v, end[0], vertex_normals(end_v, end[0]), material, end[1], end[2],
                        end[4], "cap", end[3]))

    def fitted_accessory(self, accessory: str, betas) -> tuple[Accessory, object]:
        """(the accessory fitted to the hand of `betas`, the key its rest arrays are kept under): the catalogue's
        own for no betas, else refitted (accessories.reshape). One shape's refits are kept at a time, so a dataset
        that changes shape every frame holds no more than one frame's."""
        acc = self.accessories[accessory]
        b = None if betas is None else np.asarray(betas, np.float64).reshape(-1)
        if b is None or not b.any():
            return acc, acc.id
        if self._refits is None or self._refits[0] != b.tobytes():
            for cache in (self._rest_normals, self._face_joints):
                for k in [k for k in cache if isinstance(k, tuple) and isinstance(k[1], tuple) and k[1][0] == "refit"]:
                    del cache[k]
            self._refits = (b.tobytes(), {})
        fitted = self._refits[1]
        if accessory not in fitted:
            if self._refitter is None:
                self._refitter = ShapeRefitter(self.model, list(self.accessories.values()))
            fitted[accessory] = self._refitter.refit(b, [accessory])[0]
        return fitted[accessory], ("refit", accessory)

    def posed_accessory(self, acc: Accessory, posed, key=None, move=None) -> Surface:
        """The accessory placed for a forward-pass result: rigid ones by their joint's skinning transform (after
        `move`, a (4, 4) rigid move in the rest frame: a worn ring's slide), gloves skinned with their own
        correctives. key: what its rest arrays are kept under (default its id; a refitted accessory's includes the
        shape)."""
        key = acc.id if key is None else key
        if acc.parent_joint is not None:
            G = posed.transforms[0, acc.parent_joint].astype(np.float64)
            if move is not None:
                G = G @ move
            rest_n = self._rest_normals.get(("normals", key))
            if rest_n is None:
                rest_n = self._rest_normals["normals", key] = vertex_normals(acc.vertices, acc.faces)
            v = (acc.vertices @ G[:3, :3].T + G[:3, 3]).astype(np.float32)
            n = (rest_n @ G[:3, :3].T.astype(np.float32)).astype(np.float32)
            local = self._rest_normals.get(("f32", key))
            if local is None:
                local = self._rest_normals["f32", key] = np.ascontiguousarray(acc.vertices, np.float32)
        else:
            posedirs = acc.posedirs if acc.posedirs is not None else np.zeros((len(acc.vertices), 3,
                                                                                 NUM_POSE_FEATURES))
            if ("f32", key) not in self._face_joints:
                self._face_joints["f32", key] = tuple(np.ascontiguousarray(a, np.float32)
                                                      for a in (acc.vertices, acc.weights, posedirs))
            v32, w32, d32 = self._face_joints["f32", key]
            v = pose_skinned(v32, w32, d32, posed.rotations, posed.transforms)[0]
            v = v.astype(np.float32)
            n = vertex_normals(v, acc.faces)
            if acc.id not in self._face_joints:
                assert acc.weights is not None, "a skinned accessory has weights"
                self._face_joints[acc.id] = face_joints(acc.faces, acc.weights)
        faces, uvs, faces_uv = self._static_arrays(("acc", acc.id), acc)
        return Surface(acc.id, v, faces, n, accessory_material(acc), uvs, faces_uv, acc.vertices, "accessory",
                       None if acc.parent_joint is not None else self._face_joints[acc.id],
                       *((local, G) if acc.parent_joint is not None else ()))


def texture_catalog(path) -> tuple[list[TextureSet], str | None]:
    """The texture sets of a catalogue and its default id (load_texture_catalog lists the default first)."""
    sets = load_texture_catalog(path)
    return sets, (sets[0].id if sets else None)


def accessory_material(acc: Accessory) -> Material:
    """An accessory's metallic-roughness material: its textures (base colour sRGB; glTF layout G roughness,
    B metallic), the catalogue's constants where a texture is missing."""
    m = acc.material
    base = tuple(m.get("base_color", (0.8, 0.8, 0.8))[:3])
    has_uv = acc.uvs is not None
    albedo = acc.base_color_png if has_uv else None
    mr = acc.metallic_roughness_png if has_uv else None
    maps = load_maps(albedo, data=mr, channels=(1, 2), base_color=base) if albedo or mr else constant_texture(base)
    textured = mr is not None
    return Material("pbr", maps, 3 if textured else None, float(m.get("roughness", 0.5)), 4 if textured else None,
                    float(m.get("metallic", 0.0)), name=acc.id)


def default_catalogues(model_path: str | Path) -> tuple[Path | None, Path | None]:
    """The texture and accessory catalogues of a pipeline build next to build/model/<side>.npz (None if absent)."""
    build = Path(model_path).resolve().parent.parent
    tex = build / "textures" / "catalog.json"
    acc = build / "accessories"
    return (tex if tex.is_file() else None,
            acc if (acc / "catalog.json").is_file() or any(acc.glob("*/catalog.json")) else None)


def plain_srgb(offset: float) -> np.ndarray:
    """(3,) the plain skin's sRGB colour with a skin-tone offset added, clipped to [0, 1]."""
    return np.clip(linear_to_srgb(np.array(PLAIN_SKIN)) + offset, 0, 1)
