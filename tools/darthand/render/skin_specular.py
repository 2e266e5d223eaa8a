"""Specular reflection of skin: two GGX lobes and a sheen, in place of the single lobe (shade.ggx_specular) when
`ShadingOptions.skin_specular` is 'dual'.

- Two lobes (the dual-lobe skin model of d'Eon and Luebke, GPU Gems 3 ch. 14, and of Jimenez et al.'s separable
  SSS): a sharper one (roughness LOBE_ROUGHNESS[0]) for the skin's oily film and a rougher one (LOBE_ROUGHNESS[1])
  for its dry, scaly surface, mixed LOBE_WEIGHTS, each GGX with height-correlated Smith visibility and Schlick's
  Fresnel at skin's F0 (subject.SKIN_F0 = 0.028). The lobes' roughness follows the texture's roughness map (the
  palm is rougher than the back of the hand: textures/canvas.base_roughness): each is its nominal value times the
  texel's roughness over REFERENCE_ROUGHNESS.
- A sheen (Estevez and Kulla's "Charlie" distribution, Production Friendly Microfacet Sheen BRDF, 2017, with
  Neubelt and Pettineo's visibility 1 / (4 (n.l + n.v - n.l n.v))), weight SHEEN_WEIGHT: the retro-reflective glow
  of vellus hair and the skin's surface at grazing angles. It is a layer over the lobes: they are scaled by
  1 - SHEEN_WEIGHT E_sheen(n.v) (E_sheen the sheen's directional albedo), the light the sheen took (Kulla and
  Conty's albedo scaling), so lobes and sheen together never reflect more than arrives.
- Per region (the mesh's face labels): nails are more specular than skin, the palm side less (REGION_SCALE's
  specular factors); nails are also glossier (its roughness factors) where the texture has no roughness map (the
  plain hand): a catalogue texture's map already holds them per texel (nail plates 0.3, nail polish by its
  finish, palms 0.62: textures/skin.py, overlays.py, canvas.py), and it decides.
- Ambient: each lobe's split-sum environment BRDF from Karis' analytic fit (shade.ambient_specular) and the sheen's
  directional albedo (tabulated once by quadrature, `sheen_albedo`), times the ambient light and its open fraction.

Intensities have pi folded in (lights.py): a light adds pi f (n.l) E, as in shade.py.
"""

from __future__ import annotations

import functools

import numpy as np

from darthand.jit import kernel
from darthand.model.layout import FACE_LABEL_IDS, FACE_LABELS

SKIN_SPECULAR = ("single", "dual")
LOBE_ROUGHNESS = (0.35, 0.6)         # at the reference roughness
LOBE_WEIGHTS = (0.85, 0.15)
REFERENCE_ROUGHNESS = 0.5            # the texture's roughness of the back of the hand (textures/canvas.SKIN_ROUGHNESS)
SHEEN_WEIGHT = 0.12
SHEEN_ROUGHNESS = 0.6                # perceptual (alpha = roughness^2)
# label -> (roughness factor, specular factor); labels not listed: (1, 1)
REGION_SCALE = {"nail": (0.45, 1.6), "palm": (1.0, 0.8), "finger_palmar": (1.0, 0.8)}
MIN_ROUGHNESS = 0.045               # as shade.MIN_ROUGHNESS: GGX is singular at alpha = 0
SHEEN_STEPS = 64                     # the sheen albedo table's columns over n.v in [0, 1]


def region_factors(labels: np.ndarray | None, m: int) -> tuple[np.ndarray, np.ndarray]:
    """(roughness factor (M,), specular factor (M,)) float32 of hits with face labels (M,) int (-1 unlabelled) or
    None (all 1)."""
    rough, spec = np.ones(len(FACE_LABELS) + 1, np.float32), np.ones(len(FACE_LABELS) + 1, np.float32)
    for name, (r, s) in REGION_SCALE.items():
        rough[FACE_LABEL_IDS[name]], spec[FACE_LABEL_IDS[name]] = r, s
    if labels is None:
        return np.ones(m, np.float32), np.ones(m, np.float32)
    index = np.where(labels < 0, len(FACE_LABELS), labels)
    return rough[index], spec[index]


def lobe_roughness(roughness: np.ndarray, factor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two lobes' perceptual roughness (M,) each from the texel's roughness (M,) and the region's factor."""
    scale = roughness * factor / np.float32(REFERENCE_ROUGHNESS)
    return tuple(np.clip(np.float32(r) * scale, MIN_ROUGHNESS, 1).astype(np.float32) for r in LOBE_ROUGHNESS)


def charlie_sheen(nl: np.ndarray, nv: np.ndarray, nh: np.ndarray, roughness) -> np.ndarray:
    """(M,) pi f_sheen (n.l) per unit (pi-folded) light intensity, unweighted: f_sheen = D V with Charlie's
    D = (2 + 1/a) sin(theta_h)^(1/a) / (2 pi), a = roughness^2, and V = 1 / (4 (n.l + n.v - n.l n.v))."""
    a = np.float32(roughness) ** 2
    sin2 = np.maximum(1 - nh * nh, 0)
    d = (2 + 1 / a) * sin2 ** (0.5 / a) / 2            # pi D: the 1/pi cancels the folded pi
    vis = 1 / np.maximum(4 * (nl + nv - nl * nv), 1e-7)
    return d * vis * nl


@functools.lru_cache(maxsize=4)
def sheen_albedo(roughness: float = SHEEN_ROUGHNESS) -> np.ndarray:
    """(SHEEN_STEPS,) float32 directional albedo of `charlie_sheen` (integral over the hemisphere of f_sheen n.l)
    at n.v = 0 .. 1, by a midpoint rule over (theta_l, phi_l) (256 x 128)."""
    theta = (np.arange(256) + 0.5) * (np.pi / 2) / 256
    phi = (np.arange(128) + 0.5) * np.pi / 128            # symmetric about the view's plane: half the circle, x 2
    tl, pl = np.meshgrid(theta, phi, indexing="ij")
    light = np.stack([np.sin(tl) * np.cos(pl), np.sin(tl) * np.sin(pl), np.cos(tl)])
    out = np.empty(SHEEN_STEPS, np.float64)
    for k, nv in enumerate(np.linspace(1e-3, 1, SHEEN_STEPS)):
        v = np.array([np.sqrt(1 - nv * nv), 0, nv])[:, None, None]
        h = light + v
        h /= np.linalg.norm(h, axis=0)
        value = charlie_sheen(light[2], np.full_like(light[2], nv), h[2], roughness) / np.pi     # f n.l
        out[k] = 2 * (value * np.sin(tl)).sum() * (np.pi / 2 / 256) * (np.pi / 128)
    return out.astype(np.float32)


def ggx_lobe(nl, nv, nh, vh, roughness, f0) -> np.ndarray:
    """(3, M) (or (M,) for a scalar f0) pi D Vis F (n.l) of one GGX lobe: D = a^2 / (pi ((n.h)^2 (a^2 - 1) + 1)^2),
    height-correlated Smith Vis = 0.5 / (n.l sqrt(n.v^2 (1 - a^2) + a^2) + n.v sqrt(n.l^2 (1 - a^2) + a^2)),
    Schlick's F = f0 + (1 - f0) (1 - v.h)^5, a = roughness^2 (shade.ggx_specular's model; not imported from there:
    shade.py imports this module)."""
    a2 = (roughness * roughness) ** 2
    d = nh * nh * (a2 - 1) + 1
    vis = 0.5 / np.maximum(nl * np.sqrt(nv * nv * (1 - a2) + a2) + nv * np.sqrt(nl * nl * (1 - a2) + a2), 1e-7)
    fresnel = f0 + (1 - f0) * (1 - vh) ** 5
    return a2 / (d * d) * vis * nl * fresnel


def environment_lobe(f0, roughness: np.ndarray, nv: np.ndarray) -> np.ndarray:
    """(3, M) (or (M,)) one GGX lobe's response to a uniform environment of unit radiance: Karis' analytic fit of
    the split-sum environment BRDF, F0 A + B (as shade.ambient_specular)."""
    r0 = 1 - roughness
    a004 = np.minimum(r0 * r0, np.exp2(-9.28 * nv)) * r0 + (0.0425 - 0.0275 * roughness)
    A = -1.04 * a004 + (1.04 - 0.572 * roughness)
    B = 1.04 * a004 + (0.022 * roughness - 0.04)
    return (f0 * A + B).astype(np.float32)


def sheen_directional(nv: np.ndarray) -> np.ndarray:
    """(M,) float32 the sheen's directional albedo at n.v (M,): sheen_albedo's table (n.v from 1e-3 to 1 in equal
    steps), linearly interpolated and clamped at its ends (np.interp's result on that grid, without its search)."""
    table = sheen_albedo().astype(np.float64)
    at = np.clip((np.asarray(nv, np.float64) - 1e-3) * ((SHEEN_STEPS - 1) / (1 - 1e-3)), 0, SHEEN_STEPS - 1)
    below = np.minimum(at.astype(np.int64), SHEEN_STEPS - 2)
    frac = at - below
    return (table[below] * (1 - frac) + table[below + 1] * frac).astype(np.float32)


def dual_specular(nl, nv, nh, vh, rough_a, rough_b, f0) -> np.ndarray:
    """(3, M) or (M,): the two GGX lobes' pi f (n.l), mixed LOBE_WEIGHTS."""
    return (np.float32(LOBE_WEIGHTS[0]) * ggx_lobe(nl, nv, nh, vh, rough_a, f0)
            + np.float32(LOBE_WEIGHTS[1]) * ggx_lobe(nl, nv, nh, vh, rough_b, f0))


def skin_specular_radiance(hits, roughness: np.ndarray, f0, strength: float, lights: np.ndarray,
                           reached: np.ndarray, ambient: np.ndarray, textured: bool = False,
                           environment=None) -> np.ndarray:
    """(3, M) float32 specular radiance of skin at hits (shade.Hits: normal, view, position, visible, region):
    per reached light (lights.light_table rows, reached (K, M) after shadows) the dual lobes and the sheen, plus
    their ambient part; roughness (M,) the texel's, f0 (3, M) or scalar, strength the material's specular scale;
    textured: the roughness comes from a map (the regions' roughness factors are then left out); environment: the
    frame's environment.FrameEnvironment or None: each lobe's ambient part is then its radiance prefiltered for
    the lobe's roughness along the reflection direction (the sheen's at roughness 1), added to `ambient`."""
    n, v = hits.normal, hits.view
    m = n.shape[1]
    rough_factor, spec_factor = region_factors(hits.region, m)
    if textured:
        rough_factor = np.ones(m, np.float32)
    rough_a, rough_b = lobe_roughness(roughness, rough_factor)
    nv = np.clip((n * v).sum(0), 1e-4, 1).astype(np.float32)
    scale = np.float32(strength) * spec_factor
    sheen = np.float32(SHEEN_WEIGHT) * sheen_directional(nv)
    layer = 1 - sheen
    lobe_a = np.float32(LOBE_WEIGHTS[0]) * environment_lobe(f0, rough_a, nv) * layer
    lobe_b = np.float32(LOBE_WEIGHTS[1]) * environment_lobe(f0, rough_b, nv) * layer
    if environment is None:
        env = (lobe_a + lobe_b + sheen) * ambient[:, None]
    else:
        reflect = 2 * (n * v).sum(axis=0) * n - v
        seen = environment.specular_lobes(reflect, np.stack([rough_a, rough_b, np.ones(m, np.float32)]))
        seen += ambient[None, :, None]
        env = lobe_a * seen[0] + lobe_b * seen[1] + sheen * seen[2]
    out = env * (scale if hits.visible is None else scale * hits.visible)
    out = np.array(np.broadcast_to(out, (3, m)), np.float32)          # writable: the kernel adds into it
    f32 = lambda a: np.ascontiguousarray(a, np.float32)
    _lights_kernel(f32(n), f32(v), f32(hits.position), f32(np.broadcast_to(f0, (3, m))), rough_a, rough_b,
                   f32(nv), f32(scale * layer), f32(scale), np.ascontiguousarray(lights, np.float32),
                   np.ascontiguousarray(reached, np.bool_), out)
    return out


def lights_radiance(hits, nv, rough_a, rough_b, f0, lobe_scale, sheen_scale, lights, reached) -> np.ndarray:
    """(3, M) float64: per reached light, lobe_scale (M,) x dual_specular + sheen_scale (M,) x SHEEN_WEIGHT x
    charlie_sheen, times the light's radiance (light_at). The definition in numpy; skin_specular_radiance does the
    same in _lights_kernel (the tests hold the two equal to float32 rounding)."""
    n, v = hits.normal.astype(np.float64), hits.view.astype(np.float64)
    out = np.zeros(n.shape)
    for k in range(len(lights)):
        on = np.flatnonzero(reached[k])
        direction, radiance = light_at(lights[k], hits.position[:, on].astype(np.float64))
        h = direction + v[:, on]
        h /= np.maximum(np.linalg.norm(h, axis=0), 1e-30)
        nl = np.clip((n[:, on] * direction).sum(0), 0, 1)
        nh = np.clip((n[:, on] * h).sum(0), 0, 1)
        vh = np.clip((v[:, on] * h).sum(0), 0, 1)
        lobes = dual_specular(nl, nv[on], nh, vh, rough_a[on], rough_b[on], np.asarray(f0)[:, on]) * lobe_scale[on]
        sheen = np.float32(SHEEN_WEIGHT) * charlie_sheen(nl, nv[on], nh, SHEEN_ROUGHNESS) * sheen_scale[on]
        out[:, on] += (lobes + sheen) * radiance
    return out


@kernel(error_model="numpy")
def _lights_kernel(normal, view, position, f0, rough_a, rough_b, nv, lobe_scale, sheen_scale, lights, reached, out):
    """out (3, M) += per light k (lights.light_table rows) and hit i where reached[k, i]: (lobe_scale x the two GGX
    lobes (ggx_lobe, weights LOBE_WEIGHTS, roughness rough_a, rough_b, Fresnel from f0 (3, M)) + sheen_scale x
    SHEEN_WEIGHT x charlie_sheen (SHEEN_ROUGHNESS)) x the light's radiance (over the squared distance for a point
    light). Every divisor is guarded (max(x, eps))."""
    zero, one, half = np.float32(0.0), np.float32(1.0), np.float32(0.5)
    w_a, w_b, w_s = np.float32(0.85), np.float32(0.15), np.float32(0.12)      # LOBE_WEIGHTS, SHEEN_WEIGHT (literals:
    sheen_a = np.float32(0.6) * np.float32(0.6)                              # a cached kernel would not see a
    inv_a = one / sheen_a                                                    # changed global); SHEEN_ROUGHNESS
    for k in range(lights.shape[0]):
        point = lights[k, 0] != zero
        for i in range(normal.shape[1]):
            if not reached[k, i]:
                continue
            lx, ly, lz = lights[k, 1], lights[k, 2], lights[k, 3]
            q0, q1, q2 = lights[k, 4], lights[k, 5], lights[k, 6]
            if point:
                lx, ly, lz = lx - position[0, i], ly - position[1, i], lz - position[2, i]
                dist = max(np.sqrt(lx * lx + ly * ly + lz * lz), np.float32(1e-9))
                lx, ly, lz = lx / dist, ly / dist, lz / dist
                falloff = max(dist * dist, np.float32(1e-12))
                q0, q1, q2 = q0 / falloff, q1 / falloff, q2 / falloff
            nx, ny, nz = normal[0, i], normal[1, i], normal[2, i]
            hx, hy, hz = view[0, i] + lx, view[1, i] + ly, view[2, i] + lz
            length = max(np.sqrt(hx * hx + hy * hy + hz * hz), np.float32(1e-30))
            hx, hy, hz = hx / length, hy / length, hz / length
            nl = min(max(nx * lx + ny * ly + nz * lz, zero), one)
            nh = min(max(nx * hx + ny * hy + nz * hz, zero), one)
            vh = min(max(view[0, i] * hx + view[1, i] * hy + view[2, i] * hz, zero), one)
            c = nv[i]
            a2 = rough_a[i] * rough_a[i]
            a2 = a2 * a2
            d = nh * nh * (a2 - one) + one
            vis = half / max(nl * np.sqrt(c * c * (one - a2) + a2) + c * np.sqrt(nl * nl * (one - a2) + a2),
                             np.float32(1e-7))
            lobe = w_a * (a2 / max(d * d, np.float32(1e-30)) * vis * nl)
            a2 = rough_b[i] * rough_b[i]
            a2 = a2 * a2
            d = nh * nh * (a2 - one) + one
            vis = half / max(nl * np.sqrt(c * c * (one - a2) + a2) + c * np.sqrt(nl * nl * (one - a2) + a2),
                             np.float32(1e-7))
            lobe += w_b * (a2 / max(d * d, np.float32(1e-30)) * vis * nl)
            x = one - vh
            x5 = x * x * x * x * x
            sin2 = max(one - nh * nh, zero)
            sheen = (np.float32(2.0) + inv_a) * sin2 ** (half * inv_a) * half
            sheen = sheen / max(np.float32(4.0) * (nl + c - nl * c), np.float32(1e-7)) * nl
            sheen = w_s * sheen * sheen_scale[i]
            s = lobe * lobe_scale[i]
            out[0, i] += (s * (f0[0, i] + (one - f0[0, i]) * x5) + sheen) * q0
            out[1, i] += (s * (f0[1, i] + (one - f0[1, i]) * x5) + sheen) * q1
            out[2, i] += (s * (f0[2, i] + (one - f0[2, i]) * x5) + sheen) * q2


def light_at(row: np.ndarray, position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit direction toward the light (3, M), radiance arriving (3, M) or (3, 1)) of one lights.light_table row
    at points (3, M): a directional light's own, a point light's over the squared distance."""
    colour = row[4:7].astype(np.float32)[:, None]
    if row[0] == 0:
        return np.broadcast_to(row[1:4].astype(np.float32)[:, None], position.shape), colour
    to = row[1:4].astype(np.float32)[:, None] - position
    dist = np.maximum(np.linalg.norm(to, axis=0), 1e-9)
    return to / dist, colour / np.maximum(dist * dist, 1e-12)
