"""Image-based lighting: an equirectangular environment map as a frame's light and backdrop.

The contract (schemas/lights.schema.json, field "environment"):

- A map is named by its stem (a built-in map of `render/environments/`, `list_builtin()`) or given by path (an
  equirectangular .exr or .hdr, width = 2 x height, linear RGB, no NaN, Inf or negative texel).
- The environment's radiance in direction d is map(d) x strength x white_balance, in the map's own units: a white
  Lambertian surface under a uniform map of value L renders radiance L (lights.py's pi-folded intensities).
- Direction -> texel in the environment frame E (right-handed, z up): u = atan2(d_y, -d_x) / (2 pi) + 0.5,
  v = atan2(d_z, hypot(d_x, d_y)) / pi + 0.5, v = 1 the image's top row (the map's centre column seen along E's -x).
  This is the contract's own formula, not Blender's: Blender's equirectangular lookup is u = atan2(d_y, -d_x) /
  (2 pi), half a turn away (measured by tests/render/test_cycles.py), so the Cycles tier turns each direction by
  pi about z before Cycles reads it (cycles_scene.HALF_TURN); both renderers follow the formula above.
  `rotation` turns the environment about E's z by that many degrees (d_E is looked up as Rz(-rotation) d_E).
- Frame 'camera': d_E = (-d_cam.z, d_cam.x, -d_cam.y) (OpenCV camera axes), so with rotation 0 the camera looks at
  the map's centre column, the map's up the image's up. Frame 'world': d_E = (d.x, -d.z, d.y) (the model's world,
  Y up, as glTF imported into Blender).

How the renderer lights with it (`frame_environment`), per map once (`map_lighting`, cached), then per frame a
rotation and a colour scale:

- the compact bright part (a sun, windows, lamps) as up to MAX_LIGHTS directional lights with hard shadows: every
  texel's luminance above a threshold (CLAMP_MEAN x the map's mean, or its BRIGHT_SHARE brightest solid angle,
  whichever is higher) is its excess, split by median cut (along the axis of the largest spread of the excess's
  directions, at its power's median) into clusters; a cluster is a light at its power-weighted mean direction
  carrying its power (intensity = integral of the excess radiance over the cluster's solid angle / pi); clusters
  too weak or too wide for one hard light go back to the remainder;
- the rest (the map with its luminance clamped to the threshold, and what no light took) as the ambient light
  generalised: at indirect.py's vertices its unoccluded irradiance from its order-2 spherical harmonics
  (`FrameEnvironment.irradiance`) less its radiance along the vertex's blocked rays (`FrameEnvironment.sky`, a
  blurred low-resolution level): the mean over the escaping rays, exact where nothing blocks; without those rays
  the unoccluded irradiance per normal;
- specular ambient: that remainder prefiltered by box mip levels, the level picked by the GGX lobe's width,
  looked up along the reflection direction (`FrameEnvironment.specular`).

Errors in the uniform-map and one-bright-texel cases are what tests/render/test_environment.py checks; the error
against many environment rays per pixel is measured by benchmarks/environment_light.py.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from darthand.errors import InputError
from darthand.jit import inlined, kernel
from darthand.render.image import read_image_buf

BUILTIN_DIR = Path(__file__).resolve().parent / "environments"     # package data: a pip install has them
SUFFIXES = (".exr", ".hdr")
FRAMES = ("camera", "world")
ENVIRONMENT_BACKGROUND = "environment"      # the background that is the environment itself (render_subject)
MAX_LIGHTS = 6              # directional lights taken from a map's bright part (shadow rays per hit and light;
                            # benchmarks/environment_light.py: 4 leave twice the error on the studio map)
LIGHT_WIDTH = 256           # the map's width at which lights are extracted (1.4 degree texels)
CLAMP_MEAN = 4.0            # texels brighter than this x the map's mean luminance give their excess to lights ...
BRIGHT_SHARE = 0.005        # ... or than the brightest 0.5 % of the sphere, whichever threshold is higher
MIN_SPREAD = 2.0            # degrees: a cluster of excess narrower than this (a sun) is not split further
MAX_LIGHT_SPREAD = 15.0     # degrees (power-weighted RMS): a wider cluster is left to the remainder (with few lights)
MIN_LIGHT_SHARE = 0.02      # lights weaker than this share of the strongest, or of the map's whole power, are left
                            # to the remainder (not worth their shadow rays)
SKY_WIDTH = 32              # the remainder's level the per-vertex rays look up (11 degree texels, then bilinear)
SH_WIDTH = 64               # the remainder's level projected onto spherical harmonics
MIN_WIDTH = 8               # the coarsest mip level
MAX_BACKDROP_STEP = 8       # a blurred backdrop is looked up every this many pixels at most (background_view)
NEGATIVE_NOISE = 0.05       # of the map's mean: texels above minus this are zero with codec noise; below, an error
MAPS_KEPT = 8               # maps kept read and prepared per process (all the built-in ones: a dataset drawing a map
                            # per frame prepares each once; about 9 MB each at 1024 x 512)
LUMA = np.array([0.2126, 0.7152, 0.0722])      # Rec. 709 luminance of linear RGB


# ------------------------------------------------------------------------------------------------ maps


def list_builtin() -> list[str]:
    """The built-in maps' names (stems of render/environments/*.exr), sorted. Listed again only when the folder
    changes (its modification time: a map added or removed), not on each of a frame's three lookups."""
    try:
        stamp = BUILTIN_DIR.stat().st_mtime_ns
    except OSError:
        stamp = None
    return list(_builtin_names(BUILTIN_DIR, stamp))


@functools.lru_cache(maxsize=4)
def _builtin_names(folder: Path, stamp: int | None) -> tuple[str, ...]:
    """list_builtin's names while `folder` has modification time `stamp`."""
    return tuple(sorted(p.stem for p in folder.glob("*.exr")))


def map_path(name_or_path: str | Path) -> Path:
    """The file of a map given by built-in name or path; InputError naming it when it is neither."""
    text = str(name_or_path)
    if text in list_builtin() and not Path(text).is_file():
        return BUILTIN_DIR / f"{text}.exr"
    path = Path(text)
    if not path.exists():
        raise InputError(f"environment {text!r}: neither a built-in map ({', '.join(list_builtin())}) nor a file")
    if path.suffix.lower() not in SUFFIXES:
        raise InputError(f"{path}: an environment map is an equirectangular .exr or .hdr file")
    return path


def read_map(name_or_path: str | Path) -> np.ndarray:
    """(H, 2H, 3) float32 linear RGB of a map (built-in name or path), read once per (path, mtime) and checked:
    InputError, one line naming the file, when it does not decode, is not 2:1, or holds NaN, Inf or negative values.
    Negative texels within NEGATIVE_NOISE x the map's mean of zero (a lossy codec's undershoot: the built-in maps'
    DWAB compression leaves some down to -0.002) are read as zero. The array is shared: do not write to it."""
    path = map_path(name_or_path)
    return _read_map(str(path), path.stat().st_mtime_ns)


@functools.lru_cache(maxsize=MAPS_KEPT)
def _read_map(path: str, mtime: int) -> np.ndarray:
    buf = read_image_buf(path, "environment map")        # its decoders' stderr captured, faults one line
    spec = buf.spec()
    if spec.width != 2 * spec.height:
        raise InputError(f"{path}: environment map is {spec.width}x{spec.height}, not 2:1 (equirectangular)")
    pixels = buf.get_pixels(oiio.FLOAT)
    if pixels is None:
        raise InputError(f"{path}: cannot read environment map ({buf.geterror() or 'no pixels'})")
    pixels = np.asarray(pixels, np.float32).reshape(spec.height, spec.width, spec.nchannels)
    rgb = np.repeat(pixels[..., :1], 3, axis=2) if spec.nchannels < 3 else pixels[..., :3]
    if not np.isfinite(rgb).all():
        raise InputError(f"{path}: environment map holds NaN or Inf values")
    if (rgb < -NEGATIVE_NOISE * max(float(rgb.mean()), 1e-6)).any():
        raise InputError(f"{path}: environment map holds negative values")
    rgb = np.ascontiguousarray(np.maximum(rgb, 0))      # lossy codecs' undershoot (the built-in maps' DWAB)
    rgb.setflags(write=False)
    return rgb


# ------------------------------------------------------------------------------------------------ the document


@dataclass(frozen=True)
class Environment:
    """A lights document's "environment": map (built-in name or path), rotation (degrees about E's z), strength
    (linear multiplier), white_balance (3,) linear multipliers, frame ('camera' or 'world')."""

    map: str
    rotation: float = 0.0
    strength: float = 1.0
    white_balance: tuple = (1.0, 1.0, 1.0)
    frame: str = "camera"

    @staticmethod
    def from_json(doc: dict, source: str = "lights", base: Path | None = None) -> "Environment":
        """From the document field (already schema-checked); InputError naming the source when the map is missing
        or bad. base: the folder a relative map path is relative to (a lights file's; None: the working folder)."""
        name = str(doc["map"])
        if base is not None and name not in list_builtin() and not Path(name).is_absolute():
            name = str(base / name)
        env = Environment(name, float(doc.get("rotation", 0.0)), float(doc.get("strength", 1.0)),
                          tuple(float(x) for x in doc.get("white_balance", (1.0, 1.0, 1.0))),
                          str(doc.get("frame", "camera")))
        if env.frame not in FRAMES:
            raise InputError(f"{source}: field 'environment.frame' is {env.frame!r}, not one of {', '.join(FRAMES)}")
        read_map(env.map)
        return env

    def to_json(self) -> dict:
        return {"map": self.map, "rotation": self.rotation, "strength": self.strength,
                "white_balance": list(self.white_balance), "frame": self.frame}

    @property
    def scale(self) -> np.ndarray:
        """(3,) float64 strength x white_balance."""
        return self.strength * np.asarray(self.white_balance, np.float64)


# ------------------------------------------------------------------------------------------------ directions

_CAMERA_TO_E = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
_WORLD_TO_E = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def frame_matrix(frame: str, R: np.ndarray, rotation: float = 0.0) -> np.ndarray:
    """(3, 3) M taking world directions to the map's lookup directions, d_map = Rz(-rotation) d_E: d_E from the
    world direction through the camera (R (3, 3) world -> camera) for frame 'camera', directly for 'world'."""
    to_e = _CAMERA_TO_E @ np.asarray(R, np.float64) if frame == "camera" else _WORLD_TO_E
    a = np.radians(-rotation)
    rz = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    return rz @ to_e


def env_directions(directions: np.ndarray, frame: str, R: np.ndarray, rotation: float = 0.0) -> np.ndarray:
    """(N, 3) the map's lookup directions of world directions (N, 3) (see frame_matrix)."""
    return np.asarray(directions, np.float64) @ frame_matrix(frame, R, rotation).T


def direction_uv(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u, v) in [0, 1] of lookup directions d (N, 3) (need not be unit): the contract's equirectangular formula,
    u = atan2(d_y, -d_x) / (2 pi) + 0.5, v = atan2(d_z, hypot(d_x, d_y)) / pi + 0.5 (v = 1 the top row)."""
    d = np.asarray(d, np.float64)
    u = np.arctan2(d[:, 1], -d[:, 0]) / (2 * np.pi) + 0.5
    v = np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])) / np.pi + 0.5
    return u, v


# atan(a) ~ a P(a^2) on [0, 1], P's coefficients lowest power first: a near-minimax fit of the absolute error
# (Lawson's reweighted least squares over 40,000 points of [0, 1], degree 19), at most 9e-10 rad over [0, 1]
ATAN_POLY = (0.9999999805603458, -0.33333180377005617, 0.19996436814239382, -0.14247222686275363,
             0.1087800996248231, -0.08213761781195035, 0.055028102298562157, -0.028490777197055353,
             0.009567340797516158, -0.001509303278321189)
ATAN_ERROR = 1e-9           # rad, over the whole circle (tests/render/test_environment_atan.py)


@inlined
def fast_atan2(y: float, x: float) -> float:
    """np.arctan2(y, x) (float64 scalars, radians in [-pi, pi]) to ATAN_ERROR, for the map lookups' coordinates
    (libm's arctan2 was most of their time). Octant reduction: a = min(|x|, |y|) / max(|x|, |y|) in [0, 1] (0 at
    x = y = 0), atan(a) = a P(a^2) by ATAN_POLY, then pi/2 - r past the diagonal, pi - r for x < 0 or x = -0, the
    sign of y: the signed zeros land where np.arctan2's do (the seam at +-pi, the poles at 0 or +-pi)."""
    ax, ay = abs(x), abs(y)
    a = min(ax, ay) / max(ax, ay, 5e-324)
    s = a * a
    s2 = s * s
    s4 = s2 * s2
    c = ATAN_POLY
    # Estrin's scheme: short dependency chains (Horner's one chain of ten steps took half again as long)
    p = (((c[0] + c[1] * s) + (c[2] + c[3] * s) * s2) + ((c[4] + c[5] * s) + (c[6] + c[7] * s) * s2) * s4
         + (c[8] + c[9] * s) * (s4 * s4))
    r = a * p
    r = 0.5 * math.pi - r if ay > ax else r
    r = math.pi - r if math.copysign(1.0, x) < 0 else r
    return math.copysign(r, y)


@inlined(always=True)
def map_angles(d0: float, d1: float, d2: float) -> tuple[float, float]:
    """(u, 1 - v) of a lookup direction (float64 components, need not be unit): direction_uv's u, and its v as the
    share of the map's height from the top row, with fast_atan2 for np.arctan2 and sqrt(d0^2 + d1^2) for hypot:
    what the map lookups find texel coordinates from (x = u W - 0.5, y = (1 - v) H - 0.5)."""
    return fast_atan2(d1, -d0) / (2 * np.pi) + 0.5, 0.5 - fast_atan2(d2, math.sqrt(d0 * d0 + d1 * d1)) / np.pi


def atan2_many(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(N,) float64 fast_atan2 of float64 arrays y, x (N,) (what the map lookups compute, for tests and
    benchmarks)."""
    y, x = np.ascontiguousarray(y, np.float64), np.ascontiguousarray(x, np.float64)
    out = np.empty(len(y), np.float64)
    _atan2_kernel(y, x, out)
    return out


@kernel(error_model="numpy")
def _atan2_kernel(y, x, out):
    """out[i] = fast_atan2(y[i], x[i]) over (N,) float64 arrays."""
    for i in range(out.shape[0]):
        out[i] = fast_atan2(y[i], x[i])


def texel_directions(height: int) -> np.ndarray:
    """(H, 2H, 3) unit lookup directions of the texel centres of an H x 2H map (the inverse of direction_uv)."""
    width = 2 * height
    u = (np.arange(width) + 0.5) / width
    v = 1 - (np.arange(height) + 0.5) / height
    phi, theta = 2 * np.pi * (u[None, :] - 0.5), np.pi * (v[:, None] - 0.5)
    c = np.cos(theta)
    return np.stack(np.broadcast_arrays(-c * np.cos(phi), c * np.sin(phi), np.sin(theta)), axis=-1)


def texel_solid_angles(height: int) -> np.ndarray:
    """(H, 1) the solid angle of each row's texels of an H x 2H map (steradians; they sum to 4 pi over the map)."""
    edges = np.pi * (0.5 - np.arange(height + 1) / height)          # elevation of the row boundaries, top down
    return ((np.sin(edges[:-1]) - np.sin(edges[1:])) * (2 * np.pi / (2 * height)))[:, None]


# ------------------------------------------------------------------------------------------------ mip levels


def halve(level: np.ndarray) -> np.ndarray:
    """(H/2, W/2, 3) float32: each 2 x 2 block's mean radiance weighted by its texels' solid angles (so power is
    kept)."""
    h = level.shape[0]
    w = texel_solid_angles(h)[:, :, None]
    weighted = (level * w).reshape(h // 2, 2, level.shape[1] // 2, 2, 3).sum(axis=(1, 3))
    return (weighted / w.reshape(h // 2, 2, 1, 1).sum(axis=1) / 2).astype(np.float32)


def pyramid(pixels: np.ndarray) -> list[np.ndarray]:
    """Mip levels of a map, finest first: the map at a power-of-two width (resampled by OpenImageIO when it is not
    one), then halved down to MIN_WIDTH."""
    h, w = pixels.shape[:2]
    top = max(MIN_WIDTH, 1 << int(np.floor(np.log2(w))))
    if top != w:
        buf = oiio.ImageBufAlgo.resize(oiio.ImageBuf(np.ascontiguousarray(pixels, np.float32)),
                                       roi=oiio.ROI(0, top, 0, top // 2, 0, 1, 0, 3))
        pixels = np.asarray(buf.get_pixels(oiio.FLOAT), np.float32).reshape(top // 2, top, 3)
        pixels = np.maximum(pixels, 0)               # the resampling filter's lobes may undershoot
    levels = [np.asarray(pixels, np.float32)]
    while levels[-1].shape[1] > MIN_WIDTH:
        levels.append(halve(levels[-1]))
    return levels


def level_of_width(levels: list[np.ndarray], width: int) -> np.ndarray:
    """The finest level no wider than `width` (the coarsest if all are)."""
    return next((lv for lv in levels if lv.shape[1] <= width), levels[-1])


def bilinear(level: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(N, 3) float64 bilinear lookup of a map level (H, W, 3) along lookup directions d (N, 3) (direction_uv's
    convention), wrapping in u and clamping at the poles."""
    out = np.zeros((len(d), 3), np.float64)
    _lookup_kernel(np.ascontiguousarray(level, np.float32), np.ascontiguousarray(d, np.float64), 1.0, out)
    return out


@kernel(error_model="numpy")
def _lookup_kernel(level, d, weight, out):
    """out[i] += weight x the bilinear lookup of level (H, W, 3) float32 along direction d[i] (N, 3) float64. u, v
    as direction_uv, with fast_atan2 for np.arctan2 and sqrt(d0^2 + d1^2) for hypot (the same to ~1e-9 rad, a third
    of the time); texel coordinates x = u W - 0.5, y = (1 - v) H - 0.5 (texel centres at integers), x wrapping, y
    clamped. 256 directions at a time, each step a loop of its own: their components copied out (to contiguous
    arrays, as _blurred_kernel), their texel coordinates (vectorised), their texels and fractions, then the texel
    reads."""
    h, w = level.shape[0], level.shape[1]
    corner = np.empty((4, 256), np.int64)           # y0, y1, x0, x1
    e0, e1, e2, xs, ys = np.empty(256), np.empty(256), np.empty(256), np.empty(256), np.empty(256)
    fxs, fys = np.empty(256), np.empty(256)
    for start in range(0, out.shape[0], 256):
        m = min(256, out.shape[0] - start)
        for j in range(m):
            e0[j], e1[j], e2[j] = d[start + j, 0], d[start + j, 1], d[start + j, 2]
        for j in range(m):
            u, t = map_angles(e0[j], e1[j], e2[j])
            xs[j], ys[j] = u * w - 0.5, t * h - 0.5
        for j in range(m):
            x, y = xs[j], ys[j]
            fx0, fy0 = np.floor(x), np.floor(y)
            fxs[j], fys[j] = x - fx0, y - fy0
            x0 = min(max(int(fx0), -1), w - 1)          # -1 .. w - 1 (clamped for NaN): wraps as x0 % w
            x0 = x0 + w if x0 < 0 else x0
            corner[0, j] = min(max(int(fy0), 0), h - 1)
            corner[1, j] = min(max(int(fy0) + 1, 0), h - 1)
            corner[2, j], corner[3, j] = x0, x0 + 1 if x0 + 1 < w else 0
        for j in range(m):
            y0, y1, x0, x1 = corner[0, j], corner[1, j], corner[2, j], corner[3, j]
            fx, fy = fxs[j], fys[j]
            for c in range(3):
                top = level[y0, x0, c] * (1 - fx) + level[y0, x1, c] * fx
                bottom = level[y1, x0, c] * (1 - fx) + level[y1, x1, c] * fx
                out[start + j, c] += weight * (top * (1 - fy) + bottom * fy)


def level_of_detail(levels: list[np.ndarray], angle_deg: np.ndarray) -> np.ndarray:
    """(N,) the fractional mip level whose texels (360 / width degrees) span `angle_deg` (N,), clipped to the
    levels."""
    finest = 360.0 / levels[0].shape[1]
    return np.clip(np.log2(np.maximum(angle_deg, finest) / finest), 0, len(levels) - 1)


@dataclass(frozen=True)
class PackedLevels:
    """Mip levels (H_l, 2 H_l, 3) packed for one compiled lookup: texels (T, 3) float32, every level's rows one
    after the other, finest first; offsets (L,) int64 each level's first texel; heights (L,) int64."""

    texels: np.ndarray
    offsets: np.ndarray
    heights: np.ndarray


def pack_levels(levels: list[np.ndarray]) -> PackedLevels:
    """The PackedLevels of mip levels (finest first)."""
    sizes = [lv.shape[0] * lv.shape[1] for lv in levels]
    return PackedLevels(np.ascontiguousarray(np.concatenate([lv.reshape(-1, 3) for lv in levels]), np.float32),
                        np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64),
                        np.array([lv.shape[0] for lv in levels], np.int64))


def lookup_blurred_many(packed: PackedLevels, d: np.ndarray, angle_deg: np.ndarray, scale=(1.0, 1.0, 1.0),
                        dtype=np.float64) -> np.ndarray:
    """(K, 3, N) `dtype`: the map blurred (trilinear between the mip levels whose texels span the angle) from the packed
    levels along directions d (N, 3) at each row of blur angles angle_deg (K, N) degrees, times a colour scale
    (3,) (in float64, then rounded to dtype), in one compiled pass (a direction's map coordinates found once for
    its K angles)."""
    d = np.ascontiguousarray(d, np.float64)
    angles = np.broadcast_to(np.asarray(angle_deg, np.float64), (len(angle_deg), len(d)))
    finest = 360.0 / (2 * float(packed.heights[0]))
    lod = np.maximum(angles, finest)            # level_of_detail's numbers, in place (0.4x the time)
    lod /= finest
    np.log2(lod, out=lod)
    np.clip(lod, 0, len(packed.heights) - 1, out=lod)
    out = np.empty((len(angles), 3, len(d)), dtype)
    _blurred_kernel(packed.texels, packed.offsets, packed.heights, d, lod,
                    np.asarray(scale, np.float64), out)
    return out


@kernel(error_model="numpy")
def _blurred_kernel(texels, offsets, heights, d, lods, scale, out):
    """out[k, :, i] = scale (3,) x the blurred value of direction d[i] (N, 3) float64 at fractional mip level
    lods[k, i] (K, N) float64 in [0, L - 1] over packed levels (texels (T, 3) float32, offsets, heights (L,) int64;
    level l is heights[l] x 2 heights[l]): bilinear in its two levels (as _lookup_kernel, its coordinates too) and
    linear between them, in float64, rounded once to out's dtype. NaN in d or lods gives NaN or some texel's value,
    never a read outside the texels.

    256 directions at a time, each step a loop of its own: their components copied out (to contiguous arrays:
    LLVM vectorises no loop reading d's rows in place), their map angles (vectorised), then per row k their two
    levels' texels, fractions and weights, then the texel reads (0.6x the time of one loop doing all)."""
    top = len(offsets) - 1
    e0, e1, e2, us, ts = np.empty(256), np.empty(256), np.empty(256), np.empty(256), np.empty(256)
    corner = np.empty((2, 4, 256), np.int64)            # per level (lo, lo + 1): the four texels' rows in texels
    fxs, fys, weights = np.empty((2, 256)), np.empty((2, 256)), np.empty((2, 256))
    for start in range(0, d.shape[0], 256):
        m = min(256, d.shape[0] - start)
        for j in range(m):
            e0[j], e1[j], e2[j] = d[start + j, 0], d[start + j, 1], d[start + j, 2]
        for j in range(m):
            us[j], ts[j] = map_angles(e0[j], e1[j], e2[j])
        for k in range(lods.shape[0]):
            for j in range(m):
                lod = lods[k, start + j]
                lo = min(max(int(lod), 0), top)
                frac = lod - lo
                for s in range(2):
                    level = min(lo + s, top)
                    weights[s, j] = 1 - frac if s == 0 else (frac if lo < top else 0.0)    # 0: level lo only
                    h = heights[level]
                    w = 2 * h
                    x, y = us[j] * w - 0.5, ts[j] * h - 0.5
                    fx0, fy0 = np.floor(x), np.floor(y)
                    fxs[s, j], fys[s, j] = x - fx0, y - fy0
                    x0 = min(max(int(fx0), -1), w - 1)      # -1 .. w - 1 (clamped for NaN): wraps as x0 % w
                    x0 = x0 + w if x0 < 0 else x0
                    x1 = x0 + 1 if x0 + 1 < w else 0
                    row = int(fy0)
                    y0 = offsets[level] + min(max(row, 0), h - 1) * w
                    y1 = offsets[level] + min(max(row + 1, 0), h - 1) * w
                    corner[s, 0, j], corner[s, 1, j], corner[s, 2, j], corner[s, 3, j] = (y0 + x0, y0 + x1,
                                                                                          y1 + x0, y1 + x1)
            for j in range(m):
                v0 = v1 = v2 = 0.0
                for s in range(2):
                    weight = weights[s, j]
                    if s == 1 and weight == 0:
                        continue
                    a, b, c, e = corner[s, 0, j], corner[s, 1, j], corner[s, 2, j], corner[s, 3, j]
                    fx, fy = fxs[s, j], fys[s, j]
                    gx, gy = 1 - fx, 1 - fy
                    v0 += weight * ((texels[a, 0] * gx + texels[b, 0] * fx) * gy
                                    + (texels[c, 0] * gx + texels[e, 0] * fx) * fy)
                    v1 += weight * ((texels[a, 1] * gx + texels[b, 1] * fx) * gy
                                    + (texels[c, 1] * gx + texels[e, 1] * fx) * fy)
                    v2 += weight * ((texels[a, 2] * gx + texels[b, 2] * fx) * gy
                                    + (texels[c, 2] * gx + texels[e, 2] * fx) * fy)
                out[k, 0, start + j] = v0 * scale[0]
                out[k, 1, start + j] = v1 * scale[1]
                out[k, 2, start + j] = v2 * scale[2]


# ------------------------------------------------------------------------------------------------ per map


@dataclass(frozen=True)
class MapLighting:
    """What a map lights with, in its own lookup frame, before rotation and colour scale: light_dirs (K, 3) unit
    directions toward the lights, light_power (K, 3) their pi-folded intensities; remainder: mip levels of the map
    less the lights' part (finest first); sh (9, 3) the remainder's order-2 spherical-harmonic coefficients; full:
    mip levels of the whole map (the backdrop)."""

    light_dirs: np.ndarray
    light_power: np.ndarray
    remainder: list
    sh: np.ndarray
    full: list
    packed: PackedLevels | None = None      # the remainder's levels packed for lookup_blurred_many


def map_lighting(name_or_path: str | Path) -> MapLighting:
    """A map's MapLighting, made once per (path, mtime)."""
    path = map_path(name_or_path)
    return _map_lighting(str(path), path.stat().st_mtime_ns)


@functools.lru_cache(maxsize=MAPS_KEPT)
def _map_lighting(path: str, mtime: int) -> MapLighting:
    full = pyramid(_read_map(path, mtime))
    work = level_of_width(full, LIGHT_WIDTH).astype(np.float64)
    remainder, excess = split_bright(work)
    total = float((work @ LUMA * texel_solid_angles(work.shape[0])).sum() / np.pi)
    dirs, power, kept = median_cut(excess, MAX_LIGHTS, MIN_LIGHT_SHARE * total)
    remainder = remainder + excess * ~kept[..., None]           # what no light took stays in the remainder
    levels = pyramid(remainder.astype(np.float32))
    return MapLighting(dirs, power, levels, sh_project(level_of_width(levels, SH_WIDTH)), full, pack_levels(levels))


def split_bright(level: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(remainder, excess) (H, W, 3) of a map level: a texel brighter (in luminance) than the threshold keeps the
    threshold's luminance in its own colour, the rest is its excess; remainder + excess = the level."""
    weight = texel_solid_angles(level.shape[0])
    luma = level @ LUMA
    area = np.broadcast_to(weight, luma.shape).ravel()
    mean = float((luma * weight).sum() / (4 * np.pi))
    order = np.argsort(luma.ravel())[::-1]
    top = min(int(np.searchsorted(np.cumsum(area[order]), BRIGHT_SHARE * 4 * np.pi)), len(order) - 1)
    threshold = max(CLAMP_MEAN * mean, float(luma.ravel()[order[top]]), 1e-12)
    keep = np.minimum(1.0, threshold / np.maximum(luma, 1e-30))[..., None]
    return level * keep, level * (1 - keep)


def median_cut(excess: np.ndarray, count: int, floor: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(directions (K, 3) unit toward the lights, power (K, 3) pi-folded intensities, kept (H, W) bool the texels
    they took), K <= count, of a map level's excess radiance (H, W, 3). Median cut: the cluster of the largest power
    x angular spread is split in two at the median of its power along the axis (x, y or z) of its directions' largest
    weighted spread, until `count` clusters or none spreads over more than MIN_SPREAD; clusters with less than
    MIN_LIGHT_SHARE of the strongest one's power, a luminance power below `floor` or a spread wider than
    MAX_LIGHT_SPREAD (one hard light would stand badly for it) are left to the remainder. A
    cluster's power is the integral of its radiance over its solid angle / pi, its direction the power-weighted
    mean."""
    h = excess.shape[0]
    flat_power = (excess * texel_solid_angles(h)[:, :, None] / np.pi).reshape(-1, 3)
    weight = flat_power @ LUMA
    kept = np.zeros(excess.shape[:2], bool)
    where = np.flatnonzero(weight > 0)
    if not len(where):
        return np.zeros((0, 3)), np.zeros((0, 3)), kept
    dirs = texel_directions(h).reshape(-1, 3)
    clusters = [where]
    while len(clusters) < count:
        spreads = [spread(dirs[m], weight[m]) for m in clusters]
        k = int(np.argmax([weight[m].sum() * s for m, s in zip(clusters, spreads)]))
        if spreads[k] < np.radians(MIN_SPREAD) ** 2 or len(clusters[k]) < 2:
            break
        clusters[k:k + 1] = split_cluster(clusters[k], dirs[clusters[k]], weight[clusters[k]])
    clusters.sort(key=lambda m: -weight[m].sum())
    strongest = weight[clusters[0]].sum()
    clusters = [m for m in clusters if weight[m].sum() >= max(MIN_LIGHT_SHARE * strongest, floor)
                and spread(dirs[m], weight[m]) <= np.radians(MAX_LIGHT_SPREAD) ** 2]
    out_dirs, out_power = [], []
    for members in clusters:
        mean = (dirs[members] * weight[members, None]).sum(axis=0)
        out_dirs.append(mean / np.linalg.norm(mean))
        out_power.append(flat_power[members].sum(axis=0))
        kept.reshape(-1)[members] = True
    return np.array(out_dirs).reshape(-1, 3), np.array(out_power).reshape(-1, 3), kept


def spread(dirs: np.ndarray, weight: np.ndarray) -> float:
    """The power-weighted variance of unit directions (M, 3) (squared radians, for a small cluster)."""
    mean = (dirs * weight[:, None]).sum(axis=0) / weight.sum()
    return float(((dirs - mean) ** 2 * weight[:, None]).sum() / weight.sum())


def split_cluster(members: np.ndarray, dirs: np.ndarray, weight: np.ndarray) -> list[np.ndarray]:
    """Two halves of a cluster of texels `members` (M,) with directions (M, 3) and powers (M,): split at the power
    median along the axis of largest weighted variance (ties broken by texel index: deterministic)."""
    mean = (dirs * weight[:, None]).sum(axis=0) / weight.sum()
    spread = ((dirs - mean) ** 2 * weight[:, None]).sum(axis=0)
    axis = int(np.argmax(spread))
    order = np.lexsort((members, dirs[:, axis]))
    cut = int(np.searchsorted(np.cumsum(weight[order]), weight.sum() / 2))
    cut = min(max(cut, 1), len(order) - 1)
    return [members[np.sort(order[:cut])], members[np.sort(order[cut:])]]


# ------------------------------------------------------------------------------------------------ harmonics

SH_BAND = np.array([np.pi] + [2 * np.pi / 3] * 3 + [np.pi / 4] * 5)    # the cosine lobe's convolution per band


def sh_basis(d: np.ndarray) -> np.ndarray:
    """(N, 9) the real spherical harmonics of order <= 2 at unit directions d (N, 3)."""
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    return np.stack([np.full_like(x, 0.282095), 0.488603 * y, 0.488603 * z, 0.488603 * x, 1.092548 * x * y,
                     1.092548 * y * z, 0.315392 * (3 * z * z - 1), 1.092548 * x * z, 0.546274 * (x * x - y * y)],
                    axis=1)


def sh_project(level: np.ndarray) -> np.ndarray:
    """(9, 3) coefficients of a map level (H, W, 3): the integral of radiance x basis over the sphere."""
    h = level.shape[0]
    weighted = (level * texel_solid_angles(h)[:, :, None]).reshape(-1, 3)
    return sh_basis(texel_directions(h).reshape(-1, 3)).T @ weighted


def sh_irradiance(sh: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(N, 3) irradiance / pi (the pi-folded irradiance: a white Lambertian surface's radiance) of SH radiance
    coefficients (9, 3) at unit normals (N, 3) (Ramamoorthi and Hanrahan 2001)."""
    return np.maximum(sh_basis(normals) @ (sh * SH_BAND[:, None]) / np.pi, 0.0)


# ------------------------------------------------------------------------------------------------ per frame


@dataclass
class FrameEnvironment:
    """An environment prepared for one frame's camera: `lights` (lights.world_lights' dicts, world frame) and the
    remainder's lookups in world directions. M (3, 3) world -> lookup directions; scale (3,) the colour scale."""

    lights: list
    lighting: MapLighting
    M: np.ndarray
    scale: np.ndarray

    def sky(self, directions: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """(N, 3) float32 the remainder's radiance seen along world directions (N, 3), blurred at SKY_WIDTH (what an
        indirect ray that escapes brings back); with rows (N,) bool, only those rows are looked up (the others are
        0), each the same number as without."""
        level = level_of_width(self.lighting.remainder, SKY_WIDTH)
        # every row turned, then the rows picked: OpenBLAS may round a row of a smaller product differently
        d = np.asarray(directions, np.float64) @ self.M.T
        if rows is None:
            return (bilinear(level, d) * self.scale).astype(np.float32)
        out = np.zeros((len(d), 3), np.float32)
        out[rows] = (bilinear(level, d[rows]) * self.scale).astype(np.float32)
        return out

    def irradiance(self, normals: np.ndarray) -> np.ndarray:
        """(3, N) float32 the remainder's unoccluded pi-folded irradiance at world unit normals (3, N)."""
        n = np.asarray(normals, np.float64).T @ self.M.T
        return (sh_irradiance(self.lighting.sh, n) * self.scale).T.astype(np.float32)

    def white(self, normals: np.ndarray) -> np.ndarray:
        """(3, N) float64 the radiance a white Lambertian surface renders at world unit normals (3, N), unshadowed:
        the remainder's irradiance plus each light's radiance x the cosine toward it."""
        normals = np.asarray(normals, np.float64)
        total = self.irradiance(normals).astype(np.float64)
        for light in self.lights:
            cosine = np.maximum(-np.asarray(light["direction"], np.float64) @ normals, 0.0)
            total += np.asarray(light["radiance"], np.float64)[:, None] * cosine[None]
        return total

    def specular(self, directions: np.ndarray, roughness: np.ndarray) -> np.ndarray:
        """(3, N) float32 the remainder prefiltered for GGX roughness (N,) along world reflection directions
        (3, N): blurred over about 90 alpha degrees (alpha = roughness^2, the lobe's width)."""
        return self.specular_lobes(directions, np.asarray(roughness)[None])[0]

    def specular_lobes(self, directions: np.ndarray, roughness: np.ndarray) -> np.ndarray:
        """(K, 3, N) float32: `specular` along world directions (3, N) for each row of GGX roughness (K, N)."""
        d = np.asarray(directions, np.float64).T @ self.M.T
        angle = np.asarray(roughness, np.float64) ** 2
        angle *= 90.0
        packed = self.lighting.packed or pack_levels(self.lighting.remainder)
        return lookup_blurred_many(packed, d, angle, self.scale, np.float32)


def frame_environment(environment: Environment, R: np.ndarray) -> FrameEnvironment:
    """The environment for a camera (R (3, 3) world -> camera): its map's lights turned into the world and scaled,
    its remainder's lookups."""
    M = frame_matrix(environment.frame, R, environment.rotation)
    return turned_lighting(map_lighting(environment.map), M, environment.scale)


def turned_lighting(lighting: MapLighting, M: np.ndarray, scale: np.ndarray) -> FrameEnvironment:
    """A map's lighting turned by M (3, 3) (world -> lookup directions) and scaled by scale (3,)."""
    lights = [{"type": "directional", "radiance": (p * scale).astype(np.float32), "shadows": True,
               "direction": -(M.T @ d)} for d, p in zip(lighting.light_dirs, lighting.light_power)]
    return FrameEnvironment(lights, lighting, M, scale)


def key_white(environment: Environment, lighting: MapLighting | None = None) -> float:
    """The brightest a white Lambertian surface facing the camera renders under a frame-'camera' `environment`
    (unshadowed, the largest channel, over `facing_normals()`, spread evenly over the hemisphere that faces the
    camera; the environment turns with the camera, so no camera is needed): what an exposure must keep below white
    for no skin to clip. lighting: the map's MapLighting or its light_summary (default map_lighting(map))."""
    M = frame_matrix(environment.frame, np.eye(3), environment.rotation)
    frame = turned_lighting(lighting or map_lighting(environment.map), M, environment.scale)
    return float(frame.white(facing_normals()).max())


def light_summary(lighting: MapLighting) -> MapLighting:
    """The part of a map's lighting that key_white reads (its lights and harmonics), without its mip levels: a few
    hundred bytes, kept per map where a set has more maps than MAPS_KEPT."""
    return replace(lighting, remainder=[], full=[], packed=None)


@functools.cache
def facing_normals(count: int = 512, rim: int = 64) -> np.ndarray:
    """(3, count + rim) unit normals in camera axes (OpenCV: the camera looks along +z) spread evenly over the
    hemisphere that faces the camera (a Fibonacci lattice, z from -1 to 0), plus `rim` on its rim (z = 0), where a
    light from behind the hand is brightest."""
    k = np.arange(count, dtype=np.float64)
    z = -1.0 + k / count
    r = np.sqrt(1.0 - z * z)
    phi = k * np.pi * (3.0 - np.sqrt(5.0))
    ring = np.linspace(0.0, 2 * np.pi, rim, endpoint=False)
    return np.concatenate([np.stack([r * np.cos(phi), r * np.sin(phi), z]),
                           np.stack([np.cos(ring), np.sin(ring), np.zeros(rim)])], axis=1)


def backdrop_blur(background) -> float | None:
    """The blur in degrees of a background that is the environment itself ('environment', or a dataset's
    {'environment': true, 'blur': degrees}), None for any other background."""
    if isinstance(background, str) and background == ENVIRONMENT_BACKGROUND:
        return 0.0
    if isinstance(background, dict) and background.get("environment") is True:
        return float(background.get("blur", 0.0))
    return None


def background_view(environment: Environment, camera, blur_deg: float = 0.0) -> np.ndarray:
    """(H, W, 3) float32 linear: the environment seen through `camera` (render/camera.Camera), each pixel centre's
    ray looked up in the whole map (sun included), blurred over about `blur_deg` degrees (0: bilinear at full
    resolution): `backdrop_grid`'s lookups upsampled (Backdrop.pixels)."""
    return backdrop_grid(environment, camera, blur_deg).pixels()


@dataclass(frozen=True)
class Backdrop:
    """The environment backdrop of a height x width frame as looked up: grid (h, w, 3) float32 linear, its sample
    (i, j) standing for the frame's pixel centre (step i + (step - 1) / 2, step j + (step - 1) / 2) (every pixel
    when step is 1). `pixels()` is the frame's background; a compositor may blend the grid itself (`axes`)."""

    grid: np.ndarray
    step: int
    height: int
    width: int

    def pixels(self) -> np.ndarray:
        """(height, width, 3) float32: the grid upsampled (bilinear, `upsample`)."""
        return self.grid if self.step == 1 else upsample(self.grid, self.step, self.height, self.width)

    def axes(self) -> tuple:
        """((r0, r1, fr), (c0, c1, fc)): `upsample`'s blend of the grid, per frame row and per frame column (see
        `upsample_axis`)."""
        return (upsample_axis(self.step, self.height, self.grid.shape[0]),
                upsample_axis(self.step, self.width, self.grid.shape[1]))


def backdrop_grid(environment: Environment, camera, blur_deg: float = 0.0) -> Backdrop:
    """The Backdrop of `background_view`: the whole map blurred over `blur_deg` degrees (bilinear in the two mip
    levels whose texels span it, blended by the fractional level, in float64, times the colour scale, then
    float32) along the rays of every backdrop_step-th pixel centre."""
    if not (np.isfinite(blur_deg) and 0 <= blur_deg <= 180):
        raise InputError(f"background_blur: {blur_deg!r} is not a number of degrees in 0..180")
    levels = map_lighting(environment.map).full
    step = backdrop_step(camera.K, blur_deg)
    height, width = -(-camera.height // step), -(-camera.width // step)
    # a coarse pixel centre (x, y, 1) -> the fine image point it stands for (step x, step y) -> world direction
    # R^T K^-1 p -> the lookup frame: one (3, 3) matrix (for row vectors)
    coarse = np.diag([float(step), float(step), 1.0])
    to_map = (np.linalg.inv(camera.K) @ coarse).T @ camera.R @ frame_matrix(environment.frame, camera.R,
                                                                             environment.rotation).T
    lod = float(level_of_detail(levels, np.array([float(blur_deg)]))[0])
    k, frac = int(lod), lod - int(lod)
    second = frac > 0 and k + 1 < len(levels)
    grid = np.empty((height, width, 3), np.float32)
    _backdrop_kernel(np.ascontiguousarray(levels[k], np.float32),
                     np.ascontiguousarray(levels[k + 1 if second else k], np.float32), 1 - frac, second, frac,
                     to_map, np.asarray(environment.scale, np.float64), grid)
    return Backdrop(grid, step, camera.height, camera.width)


@kernel(error_model="numpy")
def _backdrop_kernel(level, coarser, weight, second, weight2, to_map, scale, out):
    """out[i, j] (h, w, 3) float32 = scale (3,) x (weight x level's bilinear lookup (+ weight2 x coarser's when
    `second`)) along the ray of grid pixel centre (j + 0.5, i + 0.5, 1) times to_map (3, 3): _lookup_kernel's
    numbers (its coordinates, its blend, accumulated in float64 from 0, level then coarser), times scale, rounded
    to float32; the ray's map angles are found once for both levels, a grid row's at a time in a loop of their own
    (it vectorises: 0.6x the time of one loop doing both)."""
    us, ts = np.empty(out.shape[1]), np.empty(out.shape[1])
    for i in range(out.shape[0]):
        py = i + 0.5
        for j in range(out.shape[1]):
            px = j + 0.5
            d0 = px * to_map[0, 0] + py * to_map[1, 0] + to_map[2, 0]
            d1 = px * to_map[0, 1] + py * to_map[1, 1] + to_map[2, 1]
            d2 = px * to_map[0, 2] + py * to_map[1, 2] + to_map[2, 2]
            us[j], ts[j] = map_angles(d0, d1, d2)
        for j in range(out.shape[1]):
            u, t = us[j], ts[j]
            v0 = v1 = v2 = 0.0
            for k in range(2 if second else 1):
                lv = level if k == 0 else coarser
                wk = weight if k == 0 else weight2
                h, w = lv.shape[0], lv.shape[1]
                x, y = u * w - 0.5, t * h - 0.5
                fx0, fy0 = np.floor(x), np.floor(y)
                fx, fy = x - fx0, y - fy0
                x0 = int(fx0) % w
                x1 = (x0 + 1) % w
                y0 = min(max(int(fy0), 0), h - 1)
                y1 = min(max(int(fy0) + 1, 0), h - 1)
                top = lv[y0, x0, 0] * (1 - fx) + lv[y0, x1, 0] * fx
                bottom = lv[y1, x0, 0] * (1 - fx) + lv[y1, x1, 0] * fx
                v0 += wk * (top * (1 - fy) + bottom * fy)
                top = lv[y0, x0, 1] * (1 - fx) + lv[y0, x1, 1] * fx
                bottom = lv[y1, x0, 1] * (1 - fx) + lv[y1, x1, 1] * fx
                v1 += wk * (top * (1 - fy) + bottom * fy)
                top = lv[y0, x0, 2] * (1 - fx) + lv[y0, x1, 2] * fx
                bottom = lv[y1, x0, 2] * (1 - fx) + lv[y1, x1, 2] * fx
                v2 += wk * (top * (1 - fy) + bottom * fy)
            out[i, j, 0] = v0 * scale[0]
            out[i, j, 1] = v1 * scale[1]
            out[i, j, 2] = v2 * scale[2]


def backdrop_step(K: np.ndarray, blur_deg: float) -> int:
    """The pixel step at which a backdrop blurred over `blur_deg` degrees is looked up (1: every pixel): a third of
    the blur's width in pixels (focal length K[0, 0]), at most MAX_BACKDROP_STEP; the view between is bilinear,
    which a blur that wide cannot tell from the lookup (the blurred map varies over several steps: 0.3 % mean and
    5 % p99 of the mean level off the full lookup at 1.5 and 3 degrees, 512^2, 45 degrees of view)."""
    blur_px = math.radians(float(blur_deg)) * float(K[0, 0])
    return int(np.clip(blur_px // 3, 1, MAX_BACKDROP_STEP))


def upsample(image: np.ndarray, step: int, height: int, width: int) -> np.ndarray:
    """(height, width, C) float32 bilinear upsampling of a grid (h, w, C) whose sample (i, j) stands for the fine
    pixel centre (step i + (step - 1) / 2, step j + (step - 1) / 2); edges clamped."""
    r0, r1, fr = upsample_axis(step, height, image.shape[0])
    c0, c1, fc = upsample_axis(step, width, image.shape[1])
    out = np.empty((height, width, image.shape[2]), np.float32)
    _upsample_kernel(np.ascontiguousarray(image, np.float32), r0, r1, fr, c0, c1, fc, out)
    return out


def upsample_axis(step: int, n: int, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lo, hi (n,) int64, frac (n,) float32): fine pixel k of an axis of n lies between grid samples lo[k] and
    hi[k] of m, at frac[k] from lo[k] (upsample's blend: lo x (1 - frac) + hi x frac; edges clamped)."""
    x = np.clip((np.arange(n) - (step - 1) / 2) / step, 0, m - 1)
    lo = np.minimum(x.astype(np.int64), m - 1)
    hi = np.minimum(lo + 1, m - 1)
    return lo, hi, (x - lo).astype(np.float32)


@kernel
def _upsample_kernel(image, r0, r1, fr, c0, c1, fc, out):
    """out[i, j] = rows r0[i], r1[i] of image (h, w, C) float32 blended by fr[i], then columns c0[j], c1[j] of that
    row blended by fc[j] (float32, in that order: the numpy separable blend's numbers). Each output row's blended
    coarse row is made once, not again for every pixel that reads it."""
    row = np.empty((image.shape[1], image.shape[2]), np.float32)
    for i in range(out.shape[0]):
        a, b, f = r0[i], r1[i], fr[i]
        g = np.float32(1) - f
        for q in range(image.shape[1]):
            for c in range(image.shape[2]):
                row[q, c] = image[a, q, c] * g + image[b, q, c] * f
        for j in range(out.shape[1]):
            p, q, e = c0[j], c1[j], fc[j]
            h = np.float32(1) - e
            for c in range(out.shape[2]):
                out[i, j, c] = row[p, c] * h + row[q, c] * e
