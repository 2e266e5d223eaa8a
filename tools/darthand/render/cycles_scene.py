"""What the Cycles tier tells Blender about a frame: the posed subject, its materials and textures, the camera, the
lights and the environment, converted into Blender's terms (render/blender/cycles_worker.py reads them).

Frames. darthand's world is the model's (Y up, metres); Blender's is Z up, with the model placed as Blender's glTF
importer places it: (x, y, z) -> (x, -z, y) (TO_BLENDER). A camera's OpenCV axes (x right, y down, z forward) are
Blender's camera axes (x right, y up, looking down -z) with y and z flipped.

Intrinsics. The sensor is fit horizontally: lens / sensor width = fx / W, so the horizontal focal length is fx
pixels; fy != fx is a pixel aspect; the principal point is a lens shift in units of the image width (Blender's
viewplane, y up: shift_x = (W/2 - cx) / W, shift_y = (cy - H/2) (fx / fy) / W). A skewed K has no Blender camera.

Units. Light intensities have pi folded in (render/lights.py): a white Lambertian surface facing a directional light
of intensity I renders radiance I, which in Blender is a sun of irradiance pi I (W/m^2); a point light of intensity I
gives that at 1 m, which in Cycles is a point light of power P = 4 pi^2 I watts (Blender's point lights are defined
so that P watts give radiant intensity P / (4 pi^2) W/sr). tests/render/test_cycles.py checks both against closed
forms. Ambient light of intensity I is a uniform world of radiance I (its own closed form).

The environment: the lighting's own (render/environment.Environment, parsed into Lighting.environment by
lights.load_lighting; its map resolved by environment.map_path), looked up by the contract's formula (environment.py's
docstring). Cycles' Environment Texture reads a direction half a turn from that formula (HALF_TURN), so the Mapping
node turns each direction by environment.frame_matrix and the half turn before Cycles reads it.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.render.camera import Camera
from darthand.render.environment import Environment, frame_matrix, map_path, read_map
from darthand.render.image import write_png
from darthand.render.lights import Lighting, world_lights
from darthand.render.subject import Material, Subject, Surface
from darthand.render.texture import MipTexture, srgb8_to_linear_lut

TO_BLENDER = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])   # model (Y up) -> Blender (Z up)
CV_TO_BLENDER_CAMERA = np.diag([1.0, -1.0, -1.0])
# Cycles' Environment Texture reads u = atan2(d_y, -d_x) / 2pi (measured: tests/render/test_cycles.py), half a turn
# from the contract's u = atan2(d_y, -d_x) / 2pi + 0.5: a direction is turned by pi about z before Cycles reads it.
HALF_TURN = np.diag([-1.0, -1.0, 1.0])
SENSOR_MM = 36.0
CLIP_M = (1e-3, 1e4)
NAIL = 0                             # model.layout.FACE_LABELS' id of 'nail'


# ------------------------------------------------------------------------------------------------ geometry


def camera_spec(cam: Camera) -> dict:
    """The worker's camera: matrix (4, 4) Blender camera -> Blender world, lens_mm, sensor_mm, shift_x, shift_y,
    aspect [x, y], clip [near, far] m, from K, R, t and the image size."""
    K, W, H = cam.K, cam.width, cam.height
    if K[0, 1] != 0:
        raise InputError("camera: field 'K' has a skew (K[0,1] != 0), which a Blender camera cannot take")
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    aspect = [fy / fx, 1.0] if fy >= fx else [1.0, fx / fy]    # pixel aspect x:y, both >= 1 (Blender's range)
    ycor = aspect[1] / aspect[0]
    M = np.eye(4)
    M[:3, :3] = TO_BLENDER @ cam.R.T @ CV_TO_BLENDER_CAMERA
    M[:3, 3] = TO_BLENDER @ cam.centre
    return {"matrix": M.tolist(), "lens_mm": float(fx * SENSOR_MM / W), "sensor_mm": SENSOR_MM,
            "shift_x": float((W / 2 - cx) / W), "shift_y": float((cy - H / 2) * ycor / W), "aspect": aspect,
            "clip": list(CLIP_M)}


def surface_arrays(surface: Surface, k: int) -> dict:
    """The npz arrays of surface k in Blender's frame: v{k}, n{k} (N, 3) float32, f{k} (F, 3) int32, uv{k} (3F, 2)
    float32 per-corner UVs (when it has them), mi{k} (F,) int32 material slot (1 for a skin's nails, else 0)."""
    C = TO_BLENDER.astype(np.float32)
    out = {f"v{k}": np.asarray(surface.vertices, np.float32) @ C.T,
           f"n{k}": np.asarray(surface.normals, np.float32) @ C.T,
           f"f{k}": np.asarray(surface.faces, np.int32)}
    if surface.uvs is not None and surface.faces_uv is not None:
        out[f"uv{k}"] = np.asarray(surface.uvs, np.float32)[np.asarray(surface.faces_uv).reshape(-1)]
    slots = np.zeros(len(surface.faces), np.int32)
    if has_nails(surface):
        slots[np.asarray(surface.face_labels) == NAIL] = 1
    out[f"mi{k}"] = slots
    return out


def has_nails(surface: Surface) -> bool:
    """A skin surface whose labels mark nails (skin.py leaves them out of the subsurface model: so does Cycles)."""
    return surface.material.kind == "skin" and surface.face_labels is not None and bool(
        (np.asarray(surface.face_labels) == NAIL).any())


# ------------------------------------------------------------------------------------------------ materials


class MaterialFiles:
    """Material specs and their texture PNGs in `folder`, each texture written once per pyramid (per texture id and
    skin-tone offset: the same codes read through another table are another file) while it is among the last
    KEEP_TEXTURES used, and each material numbered once per distinct spec (Blender names are short)."""

    KEEP_TEXTURES = 8

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self._textures: OrderedDict = OrderedDict()   # key -> (the pyramid's storage, kept so its id is not
        self._keys: dict = {}                         # reused; its files); full spec -> short material name
        self._written = 0

    def specs(self, surface: Surface) -> list[dict]:
        """The surface's material slots: its material, then (skin with nails) the same without subsurface."""
        spec = self._spec(surface.material, subsurface=surface.material.kind == "skin")
        slots = [spec]
        if has_nails(surface):
            slots.append(self._spec(surface.material, subsurface=False))
        return slots

    def _spec(self, material: Material, subsurface: bool) -> dict:
        files = self.texture_files(material.maps)
        base = files.get("base") or {"value": [float(x) for x in files["constant"][:3]]}
        spec = {"base": base,
                "roughness": _channel(files, material.roughness_channel, material.roughness_value),
                "metallic": _channel(files, material.metallic_channel, material.metallic_value),
                "ior": ior_of_f0(material.f0), "specular_level": 0.5 * float(material.specular),
                "subsurface": {"radius": [float(r) for r in material.mfp_mm], "scale": 1e-3} if subsurface else None}
        full = repr(sorted(spec.items()))
        key = self._keys.setdefault(full, f"m{len(self._keys)}")
        return {"key": key, **spec}

    def texture_files(self, tex: MipTexture) -> dict:
        """{'base': {'image': PNG of channels 0..2, sRGB}, 'data': {channel: PNG gray}} for a texture of more
        than one texel, else {'constant': (C,) values}."""
        if tex.width * tex.height == 1:
            return {"constant": np.asarray(tex.levels[0][0, 0], np.float64)}
        decode = b"" if tex.decode is None else tex.decode.tobytes()
        key = (id(tex.flat), decode)
        if key in self._textures:
            self._textures.move_to_end(key)
        else:
            self._textures[key] = (tex.flat, self._write(tex, self._written))
            self._written += 1
            if len(self._textures) > self.KEEP_TEXTURES:
                _, (_, files) = self._textures.popitem(last=False)
                for spec in [files["base"], *files["data"].values()]:
                    Path(spec["image"]).unlink(missing_ok=True)
        return self._textures[key][1]

    def _write(self, tex: MipTexture, n: int) -> dict:
        self.folder.mkdir(parents=True, exist_ok=True)
        base = self.folder / f"tex{n}_base.png"
        write_png(base, albedo_codes(tex))
        files: dict = {"base": {"image": str(base)}, "data": {}}
        for c in range(3, tex.channels):
            path = self.folder / f"tex{n}_data{c}.png"
            write_png(path, data_codes(tex, c), srgb=False)
            files["data"][c] = {"image": str(path)}
        return files


def _channel(files: dict, channel: int | None, value: float) -> dict:
    if channel is None:
        return {"value": float(value)}
    if "constant" in files:
        return {"value": float(files["constant"][channel])}
    return files["data"][channel]


def albedo_codes(tex: MipTexture) -> np.ndarray:
    """(H, W, 3) uint8 sRGB codes of level 0's linear albedo: the stored codes themselves when the texture reads them
    through the plain sRGB table (no skin-tone offset), else the linear values re-encoded."""
    level = tex.texels(0)
    if tex.decode is not None and all(np.array_equal(tex.decode[c], srgb8_to_linear_lut(0.0)) for c in range(3)):
        return np.ascontiguousarray(level[..., :3])
    linear = tex.levels[0][..., :3]
    return encode_srgb8(linear)


def data_codes(tex: MipTexture, channel: int) -> np.ndarray:
    """(H, W) uint8 codes of a data channel (value * 255, as the textures stage stores them)."""
    if tex.decode is not None:
        return np.ascontiguousarray(tex.texels(0)[..., channel])
    return np.clip(np.rint(tex.levels[0][..., channel] * 255), 0, 255).astype(np.uint8)


def encode_srgb8(linear: np.ndarray) -> np.ndarray:
    """uint8 sRGB codes of linear values (clipped to [0, 1]): the nearest code by the sRGB transfer function."""
    x = np.clip(np.asarray(linear, np.float64), 0, 1)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return np.clip(np.rint(s * 255), 0, 255).astype(np.uint8)


def ior_of_f0(f0: float) -> float:
    """The refractive index whose normal-incidence Fresnel reflectance is f0 (f0 = ((n - 1) / (n + 1))^2)."""
    r = math.sqrt(max(float(f0), 0.0))
    return (1 + r) / (1 - r) if r < 1 else 100.0


# ------------------------------------------------------------------------------------------------ lights


def light_specs(lighting: Lighting, cam: Camera) -> list[dict]:
    """The worker's lights: a directional light is a sun of irradiance pi I, a point light one of power
    4 pi^2 I (module docstring), each with its colour's largest channel folded into the energy."""
    out = []
    for light in world_lights(lighting, cam.R, cam.t):
        radiance = np.asarray(light["radiance"], np.float64)
        peak = float(radiance.max())
        colour = (radiance / peak if peak > 0 else np.ones(3)).tolist()
        M = np.eye(4)
        if light["type"] == "directional":
            M[:3, :3] = frame_along(TO_BLENDER @ np.asarray(light["direction"], np.float64))
            spec = {"type": "SUN", "energy": math.pi * peak}
        else:
            M[:3, 3] = TO_BLENDER @ np.asarray(light["position"], np.float64)
            spec = {"type": "POINT", "energy": 4 * math.pi ** 2 * peak}
        out.append({**spec, "color": colour, "matrix": M.tolist(), "shadows": bool(light["shadows"])})
    return out


def frame_along(direction: np.ndarray) -> np.ndarray:
    """(3, 3) a rotation whose -z axis is `direction` (a sun shines along its -z)."""
    z = -np.asarray(direction, np.float64) / np.linalg.norm(direction)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


# ------------------------------------------------------------------------------------------------ environment


def environment_matrix(env: Environment, cam: Camera) -> np.ndarray:
    """(3, 3) Blender world direction -> the direction Cycles' Environment Texture is to look up, so that it reads the
    texel the contract gives: environment.frame_matrix (model world -> the contract's lookup direction) after
    Blender's world -> the model's (TO_BLENDER.T), then HALF_TURN (Cycles' own lookup)."""
    return HALF_TURN @ frame_matrix(env.frame, cam.R, env.rotation) @ TO_BLENDER.T


def euler_xyz(R: np.ndarray) -> list[float]:
    """XYZ Euler angles (radians) [a, b, c] with R = Rz(c) Ry(b) Rx(a), as Blender's Mapping node rotates."""
    if abs(R[2, 0]) < 1 - 1e-9:
        return [math.atan2(R[2, 1], R[2, 2]), -math.asin(R[2, 0]), math.atan2(R[1, 0], R[0, 0])]
    if R[2, 0] < 0:
        return [math.atan2(R[0, 1], R[1, 1]), math.pi / 2, 0.0]
    return [math.atan2(-R[0, 1], R[1, 1]), -math.pi / 2, 0.0]


def world_spec(lighting: Lighting, cam: Camera) -> dict:
    """The worker's world: the ambient radiance, plus the lighting's environment (if any): its map file
    (environment.map_path, checked by read_map: InputError, one line, before Blender sees it), rotation and colour
    scale."""
    spec: dict = {"ambient": [float(a) for a in lighting.ambient]}
    env = lighting.environment
    if env is not None:
        read_map(env.map)                     # cached per process: the fast render of the frame has read it
        spec["environment"] = {"map": str(map_path(env.map).resolve()),
                               "rotation": euler_xyz(environment_matrix(env, cam)),
                               "scale": [float(s) for s in env.scale]}
    return spec


def frame_arrays(subject: Subject, materials: MaterialFiles) -> tuple[dict, list[dict]]:
    """(npz arrays, the worker's surface specs [{name, materials}]) of a subject's surfaces. Names are unique (the
    worker keeps one object per name): a second hand's surfaces, named as the first's, get '#k' (k: their index)."""
    arrays: dict = {}
    surfaces: list = []
    for k, surface in enumerate(subject.surfaces):
        arrays.update(surface_arrays(surface, k))
        name = f"{surface.role}:{surface.name}"
        name = f"{name}#{k}" if any(s["name"] == name for s in surfaces) else name
        surfaces.append({"name": name, "materials": materials.specs(surface)})
    return arrays, surfaces
