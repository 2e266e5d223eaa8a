"""Fine relief of the skin as a bump map in the UV atlas: folds over the knuckles, the palm's flexion creases and
the creases across the palmar side of each finger joint, pores and micro-relief; applied to the shading normal
only (the silhouette, the mask and every label stay the mesh's).

The relief is a height field h (metres, along the surface normal; grooves negative) defined on the rest-pose
surface (a function of the 3D point, so it is continuous across UV seams), built once per model and atlas from the
textures stage's bake (textures/bake.py: rest position, labels, bones, the palmar side, the knuckles' wrinkle
lines, the fixed noise bank) at DETAIL_RES. It is stored as its slopes in the atlas, (dh/du, dh/dv) in metres per
uv unit, in a float mip pyramid (render/texture.py), so a lookup at the hit's footprint filters the relief like the
albedo is filtered (a far hand gets the averaged slope, not aliasing).

Bump mapping (Blinn, "Simulation of wrinkled surfaces", 1978): with P_u, P_v the face's tangents (metres per uv
unit, from the UV derivatives of the face, made tangent to the shading normal n), the displaced surface
P + h n has the normal N' = A n + s (h_u (n x P_v) + h_v (P_u x n)), A = |P_u x P_v|, s = +1 when P_u x P_v
points along n (-1 on a mirrored atlas: a left hand). `strength` scales h.

Deep grooves also hold less light than the open skin (their walls shadow their floor, which a bump map alone does
not show): a cavity factor, 1 - CAVITY x clip(-h / PALM_CREASE_DEPTH, 0, 1), stored beside the slopes, scales the
hit's shaded radiance (1 - strength (1 - cavity), as real-time cavity maps do).

The creases are placed as the palm-prints overlay places its lines (textures/overlays.py), at that overlay's
middle parameters, so they sit where the catalogue's palm-print variants draw theirs; the albedo is not changed.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np

from darthand.jit import kernel
from darthand.model.regions import hand_frame
from darthand.render.texture import MipTexture, float_pyramid
from darthand.textures.bake import Bake, bake, bake_key, prepare_model
from darthand.textures.curves import bezier, curve_distance
from darthand.textures.noise import smoothstep
from darthand.textures.overlays import finger_crease_profiles
from darthand.textures.surface import Surface as BakeSurface

MM = 1e-3
DETAIL_RES = 1024                # texels per side of the relief's atlas (a texel is about 0.2 mm on the hand)
WRINKLE_DEPTH = 0.05 * MM        # knuckle folds (the bake's wrinkle lines, 1.1 mm apart)
PALM_CREASE_DEPTH = 0.12 * MM    # heart, head and life lines at full depth
FINGER_CREASE_DEPTH = 0.09 * MM  # flexion creases across the palmar side of the finger joints
CREASE_WIDTH = 0.45 * MM         # Gaussian half-width of a crease's groove
PORE_DEPTH = 0.012 * MM          # pits where the pore-scale noise is high
RELIEF_DEPTH = 0.006 * MM        # micro-relief: the fine noise band
CAVITY = 0.2                     # light lost at the floor of a full-depth palm crease
# the palm-prints overlay's curves in its hand frame (f: wrist 0 .. knuckle line 1; s: little finger -1 .. index 1)
# at its middle parameters (heart_curve 0, head_slope 0, life_reach 0.125), and their relative depths
PALM_CURVES = (
    (((0.97, -1.3), (0.97, -0.4), (1.03, 0.15), (1.1, 0.42)), 1.0),
    (((0.93, 1.12), (0.88, 0.5), (0.8, -0.1), (0.7, -0.8)), 0.9),
    (((0.93, 1.08), (0.65, 0.475), (0.28, 0.5), (0.02, 0.62)), 1.0),
    (((-0.02, -1.25), (-0.03, 0.0), (-0.02, 1.25)), 0.5),
    (((-0.09, -1.2), (-0.1, 0.0), (-0.09, 1.2)), 0.35),
)


def relief_heights(b: Bake) -> np.ndarray:
    """(N,) float32 height (metres, grooves negative) at the bake's texels: knuckle folds on the back, palm and
    finger creases on the palm side, pores and micro-relief everywhere but on the nails."""
    f = b.fields
    skin = 1 - f["nail"]
    h = -WRINKLE_DEPTH * f["wrinkle"] * (1 - f["palmar"])
    h -= PALM_CREASE_DEPTH * palm_creases(b)
    h -= FINGER_CREASE_DEPTH * finger_creases(b)
    h -= PORE_DEPTH * smoothstep(0.8, 1.8, f["noise_pore0"]) * skin
    h += RELIEF_DEPTH * f["noise_fine0"] * skin
    return h.astype(np.float32)


def palm_creases(b: Bake) -> np.ndarray:
    """(N,) float32 in [0, 1]: the palm's main creases (PALM_CURVES), a Gaussian groove profile of half-width
    CREASE_WIDTH about each curve, faded out toward its ends, on the palm side of the palm and the first finger
    segments."""
    surface = BakeSurface(b)
    origin, f_vec, s_vec = hand_frame(surface.skeleton)
    samples, depth = [], []
    for ctrl, relative in PALM_CURVES:
        pts = bezier(np.array(ctrl), 160)
        samples.append(origin + np.outer(pts[:, 0], f_vec) + np.outer(pts[:, 1], s_vec))
        depth.append(relative * np.sin(np.pi * np.linspace(0.0, 1.0, len(pts))) ** 0.35)
    samples, depth = np.concatenate(samples), np.concatenate(depth)
    out = np.zeros(b.num_texels, np.float32)
    idx = surface.texels_of_bones([15, 16, 17, 18, 19, 20, 0, 3, 6, 9, 12])
    idx = idx[b.fields["palmar"][idx] > 0.35]
    d, t = curve_distance(samples, b.position[idx][:, [0, 2]].astype(np.float64), 4 * CREASE_WIDTH)
    nearest = np.clip(np.rint(t * (len(samples) - 1)).astype(int), 0, len(samples) - 1)
    side = smoothstep(0.35, 0.6, b.fields["palmar"][idx])
    out[idx] = np.exp(-(d / CREASE_WIDTH) ** 2) * depth[nearest] * side
    return out


def finger_creases(b: Bake) -> np.ndarray:
    """(N,) float32 in [0, 1]: a single crease at each finger's base and double creases at its two next joints,
    across the palmar side, bowed toward the tip at the sides (the palm-prints overlay's layout:
    textures/overlays.finger_crease_profiles)."""
    out = np.zeros(b.num_texels, np.float32)
    for idx, prof in finger_crease_profiles(b, BakeSurface(b), CREASE_WIDTH):
        out[idx] = prof * smoothstep(0.3, 0.55, b.fields["palmar"][idx])
    return out


def slope_image(b: Bake, heights: np.ndarray) -> np.ndarray:
    """(res, res, 2) float32 (dh/du, dh/dv), metres per uv unit, of per-texel heights (N,): central differences
    where both neighbours are stored texels (the bake's gutter holds true surface values around every island), one-
    sided where one is, 0 elsewhere. Row 0 is v = 1 (texture.py's convention), so dh/dv is minus the row step."""
    res = b.res
    stored = np.zeros(res * res, bool)
    stored[b.texel] = True
    stored = stored.reshape(res, res)
    h = np.zeros(res * res, np.float32)
    h[b.texel] = heights
    h = h.reshape(res, res)
    out = np.zeros((res, res, 2), np.float32)
    out[..., 0] = _difference(h, stored, axis=1) * res
    out[..., 1] = -_difference(h, stored, axis=0) * res
    return out


def relief_image(b: Bake, heights: np.ndarray) -> np.ndarray:
    """(res, res, 3) float32: slope_image's (dh/du, dh/dv) and the cavity factor (1 where nothing is stored)."""
    cavity = np.ones(b.res * b.res, np.float32)
    cavity[b.texel] = 1 - CAVITY * np.clip(-heights / PALM_CREASE_DEPTH, 0, 1)
    return np.concatenate([slope_image(b, heights), cavity.reshape(b.res, b.res, 1)], axis=2)


def _difference(h: np.ndarray, stored: np.ndarray, axis: int) -> np.ndarray:
    """Per texel, the step of h per texel along `axis` (central, else one-sided where only one neighbour is
    stored, else 0); 0 at texels not stored."""
    def shifted(a, by):
        out = np.zeros_like(a)
        src = [slice(None)] * 2
        dst = [slice(None)] * 2
        src[axis] = slice(max(-by, 0), a.shape[axis] - max(by, 0))
        dst[axis] = slice(max(by, 0), a.shape[axis] - max(-by, 0))
        out[tuple(dst)] = a[tuple(src)]
        return out

    ahead, behind = shifted(h, -1), shifted(h, 1)              # h[i + 1], h[i - 1]
    has_ahead, has_behind = shifted(stored, -1) & stored, shifted(stored, 1) & stored
    step = np.where(has_ahead & has_behind, 0.5 * (ahead - behind),
                    np.where(has_ahead, ahead - h, np.where(has_behind, h - behind, 0.0)))
    return np.where(stored, step, 0.0).astype(np.float32)


_RELIEFS: dict = {}
_RELIEFS_LOCK = threading.Lock()


def relief_texture(model, res: int = DETAIL_RES) -> MipTexture:
    """The pyramid (relief_image's 3 channels, float32) of a model's relief (a HandModel with UVs; a left hand's is
    its mirrored right hand's, on the same atlas), built once per process for the bake's key (geometry, UVs, labels,
    resolution and baking code: both hands of a model share one)."""
    key = bake_key(prepare_model(model), res)
    with _RELIEFS_LOCK:
        if key not in _RELIEFS:
            if len(_RELIEFS) >= 4:
                _RELIEFS.clear()
            b = bake(model, res)
            _RELIEFS[key] = float_pyramid(relief_image(b, relief_heights(b)))
        return _RELIEFS[key]


@dataclass(eq=False)
class DetailMap:
    """A model's relief, built at the first `texture()` call (a few seconds; relief_texture's process-wide cache
    after that) and kept: the handle a skin Material carries (subject.Material.detail), made once per source."""

    model: object
    res: int = DETAIL_RES
    _texture: MipTexture | None = field(default=None, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def texture(self) -> MipTexture:
        with self._lock:
            if self._texture is None:
                self._texture = relief_texture(self.model, self.res)
            return self._texture


# ------------------------------------------------------------------------------------------------ shading


def face_tangents(table: np.ndarray, prim: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(P_u, P_v) (3, M) float64: dP/du and dP/dv (metres per uv unit) of faces `prim` (M,), from a FaceData
    table's corner positions (rows 0..8) and uvs (rows 21..26): [e1 e2] = [P_u P_v] [duv1 duv2]."""
    t = table[:, prim].astype(np.float64)
    e1, e2 = t[3:6] - t[0:3], t[6:9] - t[0:3]
    du1, dv1 = t[23] - t[21], t[24] - t[22]
    du2, dv2 = t[25] - t[21], t[26] - t[22]
    det = du1 * dv2 - du2 * dv1
    inv = np.where(np.abs(det) > 1e-20, 1 / np.where(np.abs(det) > 1e-20, det, 1), 0.0)
    pu = (e1 * dv2 - e2 * dv1) * inv
    pv = (e2 * du1 - e1 * du2) * inv
    return pu, pv


def bumped_normals(normal: np.ndarray, pu: np.ndarray, pv: np.ndarray, slopes: np.ndarray, view: np.ndarray,
                   strength: float) -> np.ndarray:
    """(3, M) float32 unit shading normals of a height field with slopes (h_u, h_v) (2, M) (metres per uv unit,
    times `strength`) on surfaces of unit normals `normal` (3, M) and tangents pu, pv (3, M) (see the module doc),
    bent back into the visible hemisphere (n.v >= 1e-3, as shade._hits_kernel does) where the bump turns them
    away from the viewer (view (3, M) unit)."""
    n = normal.astype(np.float64)
    pu = pu - n * np.einsum("im,im->m", pu, n)           # tangent to the shading normal
    pv = pv - n * np.einsum("im,im->m", pv, n)
    cross = np.cross(pu, pv, axis=0)
    area = np.linalg.norm(cross, axis=0)
    sign = np.where(np.einsum("im,im->m", cross, n) < 0, -1.0, 1.0)
    hu, hv = slopes[0] * strength, slopes[1] * strength
    bent = n * area + sign * (hu * np.cross(n, pv, axis=0) + hv * np.cross(pu, n, axis=0))
    bent = np.where(area > 1e-20, bent, n)
    bent /= np.maximum(np.linalg.norm(bent, axis=0), 1e-30)
    v = view.astype(np.float64)
    nv = np.einsum("im,im->m", bent, v)
    low = nv < 1e-3
    if low.any():
        bent[:, low] += (1e-3 - nv[low]) * v[:, low]
        bent[:, low] /= np.linalg.norm(bent[:, low], axis=0)
    return bent.astype(np.float32)


def detail_at(hits, table: np.ndarray, prim: np.ndarray, texture: MipTexture,
              strength: float) -> tuple[np.ndarray, np.ndarray]:
    """(normals (3, M) float32, occlusion (M,) float32) of hits (shade.Hits with uv and footprint) on faces `prim` of
    a FaceData table, from the relief `texture` (relief_texture) looked up at the hits' footprint: the shading
    normals bumped (face_tangents and bumped_normals in one compiled pass, _bump_kernel; the tests hold it to the
    numpy definition), and the cavity's factor on the radiance, 1 - strength (1 - cavity), at least 0."""
    texels = texture.sample(hits.uv, texture.lod_of_footprint(hits.footprint))
    out = np.empty(hits.normal.shape, np.float32)
    f32 = lambda a: np.ascontiguousarray(a, np.float32)
    _bump_kernel(f32(table), np.ascontiguousarray(prim, np.int64), f32(hits.normal), f32(hits.view),
                 f32(texels[:2]), np.float64(strength), out)
    occlusion = np.maximum(1 - np.float32(strength) * (1 - texels[2]), 0).astype(np.float32)
    return out, occlusion


@kernel(error_model="numpy")
def _bump_kernel(table, prim, normal, view, slopes, strength, out):
    """out (3, M) = bumped_normals(normal, *face_tangents(table, prim), slopes, view, strength), per hit in float64
    (rounded to float32 once)."""
    tiny = 1e-20
    for i in range(prim.shape[0]):
        f = prim[i]
        e1 = (np.float64(table[3, f]) - table[0, f], np.float64(table[4, f]) - table[1, f],
              np.float64(table[5, f]) - table[2, f])
        e2 = (np.float64(table[6, f]) - table[0, f], np.float64(table[7, f]) - table[1, f],
              np.float64(table[8, f]) - table[2, f])
        du1, dv1 = np.float64(table[23, f]) - table[21, f], np.float64(table[24, f]) - table[22, f]
        du2, dv2 = np.float64(table[25, f]) - table[21, f], np.float64(table[26, f]) - table[22, f]
        det = du1 * dv2 - du2 * dv1
        inv = 1.0 / det if abs(det) > tiny else 0.0
        n0, n1, n2 = np.float64(normal[0, i]), np.float64(normal[1, i]), np.float64(normal[2, i])
        pu0, pu1, pu2 = (e1[0] * dv2 - e2[0] * dv1) * inv, (e1[1] * dv2 - e2[1] * dv1) * inv, \
            (e1[2] * dv2 - e2[2] * dv1) * inv
        pv0, pv1, pv2 = (e2[0] * du1 - e1[0] * du2) * inv, (e2[1] * du1 - e1[1] * du2) * inv, \
            (e2[2] * du1 - e1[2] * du2) * inv
        t = pu0 * n0 + pu1 * n1 + pu2 * n2
        pu0, pu1, pu2 = pu0 - n0 * t, pu1 - n1 * t, pu2 - n2 * t
        t = pv0 * n0 + pv1 * n1 + pv2 * n2
        pv0, pv1, pv2 = pv0 - n0 * t, pv1 - n1 * t, pv2 - n2 * t
        c0, c1, c2 = pu1 * pv2 - pu2 * pv1, pu2 * pv0 - pu0 * pv2, pu0 * pv1 - pu1 * pv0
        area = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        b0, b1, b2 = n0, n1, n2
        if area > tiny:
            sign = -1.0 if c0 * n0 + c1 * n1 + c2 * n2 < 0 else 1.0
            hu, hv = slopes[0, i] * strength * sign, slopes[1, i] * strength * sign
            # n area + sign (hu (n x pv) + hv (pu x n))
            b0 = n0 * area + hu * (n1 * pv2 - n2 * pv1) + hv * (pu1 * n2 - pu2 * n1)
            b1 = n1 * area + hu * (n2 * pv0 - n0 * pv2) + hv * (pu2 * n0 - pu0 * n2)
            b2 = n2 * area + hu * (n0 * pv1 - n1 * pv0) + hv * (pu0 * n1 - pu1 * n0)
        length = max(np.sqrt(b0 * b0 + b1 * b1 + b2 * b2), 1e-30)
        b0, b1, b2 = b0 / length, b1 / length, b2 / length
        v0, v1, v2 = np.float64(view[0, i]), np.float64(view[1, i]), np.float64(view[2, i])
        nv = b0 * v0 + b1 * v1 + b2 * v2
        if nv < 1e-3:
            b0, b1, b2 = b0 + (1e-3 - nv) * v0, b1 + (1e-3 - nv) * v1, b2 + (1e-3 - nv) * v2
            length = max(np.sqrt(b0 * b0 + b1 * b1 + b2 * b2), 1e-30)
            b0, b1, b2 = b0 / length, b1 / length, b2 / length
        out[0, i], out[1, i], out[2, i] = np.float32(b0), np.float32(b1), np.float32(b2)
