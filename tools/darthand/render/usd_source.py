"""The USD source of frames: a built package (build/usd/<side>/<side>.usda), its `texture` and `accessory` variants
selected, posed by OpenUSD's own UsdSkel maths (export.usd_evaluate.skinned_points) at a gesture's time code.

Everything the frame needs is read from the package: the skinned points of the hand and the accessory, their
triangles and face-varying `st`, the UsdPreviewSurface materials' texture files, the joints (skeleton-space joint
transforms), the skin weights (for keypoint visibility). Only the fingertip vertex ids are not in the package;
they come from asset.json's model.tip_ids when the exporter writes them, else from the model the package was built
from (the `model` argument, or build/model/<side>.npz beside the build's usd/ folder).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from pxr import Usd, UsdGeom, UsdShade, UsdSkel

from darthand.errors import InputError
from darthand.export.influences import dense_weights
from darthand.export.package_files import check_usd_package, read_asset_info
from darthand.export.usd_evaluate import skinned_points
from darthand.model.hand_model import HandModel
from darthand.model.layout import KEYPOINT_ORDERS, NUM_JOINTS
from darthand.model.load import load_model
from darthand.model.topology import face_joints, vertex_normals
from darthand.render.subject import Material, Subject, Surface, skin_material
from darthand.render.texture import constant_texture, load_maps

ROLE_KEY = "darthand:role"   # customData of the package's meshes: hand, forearm_cap, accessory


class UsdPackage:
    """An opened package; `subject(...)` poses it for a gesture with the chosen variants: a `FrameSource`
    (render/source.py) of kind 'usd', its baked gestures and shape only."""

    kind = "usd"
    worn_rings = False            # a package poses its rings rigidly, as every package does

    def __init__(self, interface: Path, stage: Usd.Stage, info: dict, tip_ids: np.ndarray):
        self.interface = interface
        self.stage = stage
        self.info = info
        self.tip_ids = tip_ids
        self.root = stage.GetDefaultPrim()
        names = stage.GetRootLayer().customLayerData.get("darthand:gestures")
        self.gestures = list(names) if names else list(info.get("gestures", {}).get("names", []))
        self.side = info.get("side") or ("left" if "left" in interface.stem else "right")

    @classmethod
    def open(cls, path, model=None) -> "UsdPackage":
        """A package from its folder or interface layer; `model` (HandModel or path) supplies the fingertip ids
        when asset.json does not."""
        path = Path(path)
        info = read_asset_info(path if path.is_dir() else path.parent)
        interface = path / info.get("interface", f"{path.name}.usda") if path.is_dir() else path
        if not os.path.lexists(interface):
            raise InputError(f"{interface}: no USD interface layer here")
        check_usd_package(interface)        # nothing outside the package, no FIFO, before OpenUSD opens anything
        stage = Usd.Stage.Open(str(interface))
        if stage is None or not stage.GetDefaultPrim():
            raise InputError(f"{interface}: not a darthand USD package (no default prim)")
        return cls(interface, stage, info, _tip_ids(interface, info, model))

    @property
    def source(self) -> str:
        return str(self.interface)

    def relabel(self, name: str) -> None:
        self.interface = Path(name)

    def pose_model(self) -> None:
        return None

    def gesture_names(self) -> list[str]:
        return list(self.gestures)

    def accessory_type(self, accessory_id: str) -> None:
        return None

    def describe(self) -> dict:
        """What a dataset's writers need of the hand: a package's parameters are not MANO's."""
        return {"source": "usd", "format": "usd"}

    def texture_ids(self) -> list[str]:
        return list(self.root.GetVariantSet("texture").GetVariantNames())

    def accessory_ids(self) -> list[str]:
        return list(self.root.GetVariantSet("accessory").GetVariantNames())

    def time_code(self, pose) -> tuple[int, str | None]:
        """The time code of a gesture name (or an int time code; None: the first, the rest pose)."""
        if pose is None:
            return 0, self.gestures[0] if self.gestures else None
        if isinstance(pose, (int, np.integer)):
            if not 0 <= int(pose) < max(1, len(self.gestures)):
                raise InputError(f"pose: time code {pose} is outside the package's 0..{len(self.gestures) - 1}")
            return int(pose), self.gestures[int(pose)] if self.gestures else None
        if isinstance(pose, str) and pose in self.gestures:
            return self.gestures.index(pose), pose
        raise InputError(f"pose: a USD package renders its gestures ({', '.join(self.gestures)}) or a time code; "
                         f"got {pose if isinstance(pose, str) else type(pose).__name__}")

    def select(self, texture: str | None, accessory: str | None) -> tuple[str, str]:
        """Set the variant selections (in the session layer, the files are not touched); returns them."""
        sel = []
        for vset, value in (("texture", texture), ("accessory", accessory)):
            vs = self.root.GetVariantSet(vset)
            names = vs.GetVariantNames()
            value = value or vs.GetVariantSelection() or (names[0] if names else "")
            if value not in names:
                raise InputError(f"{vset}: {value!r} is not a variant of {self.interface} ({', '.join(names)})")
            with Usd.EditContext(self.stage, self.stage.GetSessionLayer()):
                vs.SetVariantSelection(value)
            sel.append(value)
        return sel[0], sel[1]

    def subject(self, pose=None, *, texture: str | None = None, skin_tone_offset: float = 0.0,
                accessory: str | None = None, keypoint_order: str = "openpose", betas=None) -> Subject:
        """The package posed at the gesture's time code with the chosen variants."""
        if betas is not None:
            raise InputError("betas: a USD package carries no shape space")
        t, gesture = self.time_code(pose)
        texture, accessory = self.select(texture, accessory)
        points = skinned_points(self.stage, [t])
        meshes = role_meshes(self.root)
        surfaces = []
        # Surface order: 0 hand, 1 accessory, then the cap (frames index surfaces so).
        for role, kind in (("hand", "hand"), ("accessory", "accessory"), ("forearm_cap", "cap")):
            prim = meshes.get(role)
            if prim is None:
                continue
            key = str(prim.GetPath())
            if key not in points:
                raise InputError(f"{self.interface}: {key} is not skinned to the skeleton")
            surfaces.append(_surface(prim, points[key][0], kind, skin_tone_offset,
                                     name={"hand": texture, "accessory": accessory}.get(role, role)))
        if not surfaces or surfaces[0].role != "hand":
            raise InputError(f"{self.interface}: no hand mesh (a Mesh with customData {ROLE_KEY} = 'hand') under "
                             f"{self.root.GetPath()}")
        joints = self.joints(t)
        hand_v = surfaces[0].vertices.astype(np.float64)
        if self.tip_ids.max() >= len(hand_v):
            raise InputError(f"{self.interface}: fingertip ids do not fit the hand mesh ({len(hand_v)} points)")
        kp = np.concatenate([joints, hand_v[self.tip_ids]])[KEYPOINT_ORDERS[keypoint_order]]
        poses = self.info.get("gestures", {}).get("poses")
        pose_vec = np.asarray(poses[t], np.float64) if poses and t < len(poses) else np.zeros(3 * NUM_JOINTS)
        acc_prim = meshes.get("accessory")
        parent = _rigid_joint(acc_prim) if acc_prim else None
        info = {"source": str(self.interface), "texture": texture, "skin_tone_offset": float(skin_tone_offset),
                "accessory": accessory, "gesture": gesture, "accessory_parent_joint": parent, "time_code": t}
        return Subject(tuple(surfaces), joints, kp, self.side, pose_vec, keypoint_order, info)

    def joints(self, t: int) -> np.ndarray:
        """(16, 3) posed joint centres: the translations of the skeleton-space joint transforms (the package's
        joints' origins are the joint centres whatever their orientation, so these are MANO's posed joints)."""
        cache = UsdSkel.Cache()
        root = UsdSkel.Root(self.root)
        cache.Populate(root, Usd.PrimDefaultPredicate)
        for binding in cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate):
            query = cache.GetSkelQuery(binding.GetSkeleton())
            xf = np.asarray(query.ComputeJointSkelTransforms(Usd.TimeCode(t)), np.float64).reshape(-1, 4, 4)
            return xf[:, 3, :3].copy()         # Gf matrices act on row vectors: the translation is the last row
        raise InputError(f"{self.interface}: no skeleton binding under {self.root.GetPath()}")


# ------------------------------------------------------------------------------------------------ reading prims


def role_meshes(root: Usd.Prim) -> dict:
    """{role: Mesh prim} of the meshes under `root` that carry customData darthand:role (the first of each)."""
    out = {}
    for prim in Usd.PrimRange(root):
        role = prim.GetCustomDataByKey(ROLE_KEY) if prim.IsA(UsdGeom.Mesh) else None
        if role and role not in out:
            out[role] = prim
    return out


def _surface(prim: Usd.Prim, points: np.ndarray, role: str, offset: float, name: str) -> Surface:
    mesh = UsdGeom.Mesh(prim)
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get())
    if (counts != 3).any():
        raise InputError(f"{prim.GetPath()}: only triangle meshes are rendered")
    faces = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), np.int32).reshape(-1, 3)
    uvs = faces_uv = None
    st = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
    if st and st.HasValue():
        values = np.asarray(st.Get(), np.float32).reshape(-1, 2)
        indices = st.GetIndices()
        if st.GetInterpolation() == UsdGeom.Tokens.faceVarying:
            idx = np.asarray(indices, np.int32) if indices else np.arange(3 * len(faces), dtype=np.int32)
            uvs, faces_uv = values, idx.reshape(-1, 3)
        elif st.GetInterpolation() in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying):
            uvs, faces_uv = (values[np.asarray(indices)] if indices else values), faces
    v = np.asarray(points, np.float32)
    material = _material(prim, role, offset, name, has_uvs=uvs is not None)
    weights = _dense_weights(prim, len(v))
    return Surface(str(prim.GetPath()), v, faces, vertex_normals(v, faces), material, uvs, faces_uv,
                   np.asarray(mesh.GetPointsAttr().Get(), np.float64), role,
                   None if weights is None else face_joints(faces, weights))


def _material(prim: Usd.Prim, role: str, offset: float, name: str, has_uvs: bool) -> Material:
    """The bound UsdPreviewSurface as a Material: diffuseColor (texture or constant), roughness and metallic
    (texture channels or constants). The hand's is skin."""
    bound = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
    surface = bound.ComputeSurfaceSource()[0] if bound else None
    if not surface:
        return skin_material(name=name) if role in ("hand", "cap") else Material(name=name)

    def read(input_name, default):
        inp = surface.GetInput(input_name)
        if not inp:
            return default, None, None
        src = inp.GetConnectedSource()
        if src and has_uvs:
            shader = UsdShade.Shader(src[0].GetPrim())
            asset = shader.GetInput("file").Get() if shader.GetInput("file") else None
            if asset is not None and asset.resolvedPath:
                return inp.Get() if inp.Get() is not None else default, asset.resolvedPath, str(src[1])
        value = inp.Get()
        return (default if value is None else value), None, None

    base, albedo_file, _ = read("diffuseColor", (0.8, 0.8, 0.8))
    rough, rough_file, rough_ch = read("roughness", 0.5)
    metal, metal_file, metal_ch = read("metallic", 0.0)
    channel = {"r": 0, "g": 1, "b": 2, "a": 3}
    data = rough_file or metal_file
    if rough_file and metal_file and rough_file != metal_file:
        metal_file = None                       # one data image per material; metallic falls back to its value
    channels = [channel.get(rough_ch, 0)] if rough_file else []
    if metal_file:
        channels.append(channel.get(metal_ch, 2))
    if albedo_file or data:
        maps = load_maps(albedo_file, offset=offset if role in ("hand", "cap") else 0.0, data=data,
                         channels=channels or (0,), base_color=tuple(base))
    else:
        maps = constant_texture(base)
    rc = 3 if rough_file else None
    mc = (3 + len(channels) - 1) if metal_file else None
    if role in ("hand", "cap"):
        return skin_material(maps, rc, float(rough), name=name)
    return Material("pbr", maps, rc, float(rough), mc, float(metal), name=name)


def _dense_weights(prim: Usd.Prim, n: int) -> np.ndarray | None:
    """(N, 16) skin weights of a per-point skinned prim; None for a rigid (constant) binding."""
    binding = UsdSkel.BindingAPI(prim)
    idx_pv, w_pv = binding.GetJointIndicesPrimvar(), binding.GetJointWeightsPrimvar()
    if not idx_pv or _rigid_joint(prim) is not None:
        return None
    k = idx_pv.GetElementSize()
    return dense_weights(np.asarray(idx_pv.Get(), np.int64).reshape(n, k),
                         np.asarray(w_pv.Get(), np.float64).reshape(n, k))


def _rigid_joint(prim: Usd.Prim) -> int | None:
    """The one joint a rigidly bound prim follows (a constant binding, or every point on one joint), else None."""
    pv = UsdSkel.BindingAPI(prim).GetJointIndicesPrimvar()
    if not pv:
        return None
    idx = np.asarray(pv.Get())
    if pv.GetInterpolation() == UsdGeom.Tokens.constant or (pv.GetElementSize() == 1 and len(idx) and
                                                             (idx == idx[0]).all()):
        return int(idx[0])
    return None


def _tip_ids(interface: Path, info: dict, model) -> np.ndarray:
    tips = (info.get("model") or {}).get("tip_ids")
    if tips is not None:
        return np.asarray(tips, np.int64)

    if isinstance(model, HandModel):
        return model.tip_ids
    side = info.get("side") or interface.stem
    candidates = [Path(model)] if model is not None else [interface.parent.parent.parent / "model" / f"{side}.npz"]
    for path in candidates:
        if path.is_file():
            return load_model(path).tip_ids
    raise InputError(f"{interface}: the package does not list its fingertip vertices (asset.json model.tip_ids); "
                     f"give the model it was built from (--model build/model/{side}.npz)")

