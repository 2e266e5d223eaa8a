"""Shading in linear light: surface attributes at ray hits, a skin and a metallic-roughness BRDF, lights with hard
shadows.

Written here (not taken from a library) because no package in the project shades Embree hits; the models are the
usual real-time ones, vectorised over every hit of a batch:

- Skin diffuse, by `ShadingOptions.skin`: 'subsurface' (skin.py: the diffusion profile pre-integrated over the
  surface's curvature, per channel, nails excluded); 'wrap', wrap lighting per channel, max(0, (n.l + w) / (1 + w))
  (GPU Gems 1, ch. 16; w = 0 is Lambert, a larger red w lets red light reach past the terminator, but it adds
  light rather than moving it: not energy-conserving); 'lambert'.
- Metallic-roughness (accessories): Lambert diffuse of albedo (1 - metallic); specular F0 = mix(f0, albedo,
  metallic).
- Specular: GGX distribution, height-correlated Smith visibility, Schlick's Fresnel; alpha = roughness^2.
- Ambient: albedo (1 - metallic) ambient, plus an ambient specular from Karis' analytic fit of the split-sum
  environment BRDF ("Physically Based Shading on Mobile", 2014), so that metals are not black without a highlight.
  With indirect light (indirect.py, `ShadingOptions.ao_rays` > 0) the diffuse part is albedo times the indirect
  irradiance at the hit (the ambient light's visible part and light interreflected from other surfaces), and the
  specular part is scaled by the open fraction V (a common stand-in for specular occlusion).
- Intensities have pi folded in (lights.py): radiance = pi BRDF E cos, i.e. albedo E cos for a Lambert surface.
- Texture filtering: the mip level comes from the sample's footprint in the texture: a pixel at depth z spans
  z / f metres facing the camera, stretched by 1 / |cos| of the angle between the ray and the face (the longer
  axis of the footprint, as OpenGL's isotropic rule takes), times the face's uv units per metre
  (sqrt(uv area / area)); for a face whose UV map is not sheared this is what ray differentials give.
- Shadows: one occlusion ray per (sample, light) that the light can reach. Its origin is lifted off the surface
  along the shading normal by SHADOW_LIFT x the scene's size (0.5 mm on a hand-sized scene): more than a coarse
  mesh's facets deviate from the smooth surface (no shadow acne at the terminator), and enough that the wrap
  lighting just past the terminator is not cut off by the surface's own facets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darthand.errors import InputError
from darthand.jit import kernel
from darthand.render.skin import skin_width, subsurface_diffuse
from darthand.render.subject import Material

SHADOW_LIFT = 2e-3          # shadow-ray origin offset, relative to the scene's bounding-box diagonal
MIN_ROUGHNESS = 0.045       # GGX is singular at alpha = 0
DEFAULT_AO_RAYS = 16        # ambient-occlusion rays per vertex (benchmarks/render_reference.py: speed against error)
SKIN_MODELS = ("subsurface", "wrap", "lambert")
FACE_ROWS = (0, 9, 18, 21, 27)  # scene.FaceData's POSITION, NORMAL, GEOMETRIC, UV, UV_SCALE rows, as _hits_kernel reads them
DEFAULT_SKIN = "subsurface"


@dataclass(frozen=True)
class ShadingOptions:
    """How a frame is shaded beyond the direct lights (indirect.py): ao_rays, rays per vertex for the ambient light's
    occlusion and the interreflected light (0: ambient light is never blocked, nothing is interreflected);
    interreflection, add light reflected between surfaces (False: ambient occlusion only); skin, the skin's diffuse
    model (SKIN_MODELS: 'subsurface', 'wrap' the earlier look, 'lambert')."""

    ao_rays: int = DEFAULT_AO_RAYS
    interreflection: bool = True
    skin: str = DEFAULT_SKIN

    def __post_init__(self):
        if isinstance(self.ao_rays, bool) or not (isinstance(self.ao_rays, (int, np.integer))
                                                  and 0 <= self.ao_rays <= 4096):
            raise InputError(f"ao_rays: {self.ao_rays!r} is not a whole number of rays in 0..4096")
        if not isinstance(self.interreflection, (bool, np.bool_)):
            raise InputError(f"interreflection: {self.interreflection!r} is not true or false")
        if self.skin not in SKIN_MODELS:
            raise InputError(f"skin: {self.skin!r} is not one of {', '.join(SKIN_MODELS)}")

    def to_json(self) -> dict:
        return {"ao_rays": int(self.ao_rays), "interreflection": bool(self.interreflection), "skin": self.skin}


@dataclass
class Hits:
    """Surface attributes at M ray hits on one surface, float32, component-major: position, normal (shading, facing
    the viewer), view (unit, toward the camera) (3, M); uv (2, M) or None; footprint (M,) the longer side of the
    sample's footprint in uv units, or None; indirect (3, M) the indirect irradiance and visible (M,) the ambient
    light's open fraction (indirect.VertexLight.at), or None (the ambient light reaches everything unblocked);
    radius (M,) the surface's curvature radius (skin.surface_radius) and skin (M,) bool, not a nail, for the
    subsurface skin model, or None."""

    position: np.ndarray
    normal: np.ndarray
    view: np.ndarray
    uv: np.ndarray | None
    footprint: np.ndarray | None
    indirect: np.ndarray | None = None
    visible: np.ndarray | None = None
    radius: np.ndarray | None = None
    skin: np.ndarray | None = None


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(M,) dot products of (3, M) vectors."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _normalize(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.sqrt(_dot(v, v)), np.float32(1e-30))


def surface_hits(faces, prim: np.ndarray, bu: np.ndarray, bv: np.ndarray, directions: np.ndarray,
                 depth: np.ndarray, pixel_angle: float) -> Hits:
    """Interpolate a surface's attributes (scene.FaceData) at ray hits: faces `prim` (M,), barycentrics
    (1 - bu - bv, bu, bv). directions (3, M) float32 with camera z = 1 (so `depth` is the ray parameter);
    pixel_angle: the sample's footprint at unit depth (1 / focal length in pixels, times the sample's share of a
    pixel)."""
    if (faces.POSITION, faces.NORMAL, faces.GEOMETRIC, faces.UV, faces.UV_SCALE) != FACE_ROWS:
        raise AssertionError("scene.FaceData's rows moved: update shade.FACE_ROWS and _hits_kernel")
    m = len(prim)
    position, normal, view = (np.empty((3, m), np.float32) for _ in range(3))
    uv = np.empty((2, m if faces.has_uvs else 0), np.float32)
    footprint = np.empty(m if faces.has_uvs else 0, np.float32)
    f32 = lambda a: np.ascontiguousarray(a, np.float32)
    _hits_kernel(faces.table, np.ascontiguousarray(prim, np.int64), f32(bu), f32(bv), f32(directions), f32(depth),
                 np.float32(pixel_angle), position, normal, view, uv, footprint)
    if not faces.has_uvs:
        uv = footprint = None
    return Hits(position, normal, view, uv, footprint)


@kernel
def _hits_kernel(table, prim, bu, bv, directions, depth, pixel_angle, position, normal, view, uv, footprint):
    """`surface_hits` per hit, one pass: the face's row of the FaceData table (K, F), barycentric interpolation
    (w0 a + bu b + bv c, w0 = 1 - bu - bv), the shading normal normalised, turned to the viewer's side of the face
    and bent back into the visible hemisphere where n.v < 1e-3 (silhouettes), the unit view vector, and with
    UVs (uv, footprint non-empty) uv and the footprint's longer side (uv scale x depth x pixel angle / |cos|).
    Float32 arithmetic in the order of the numpy version it replaced (dots summed x, y, z; v / max(|v|, 1e-30))."""
    P, N, G, U, S = 0, 9, 18, 21, 27          # FACE_ROWS (literals: a cached kernel would not see a changed global)
    tiny, small, one = np.float32(1e-30), np.float32(1e-3), np.float32(1.0)
    with_uv = uv.shape[1] > 0
    for i in range(prim.shape[0]):
        f = prim[i]
        b1, b2 = bu[i], bv[i]
        b0 = one - b1 - b2
        dx, dy, dz = directions[0, i], directions[1, i], directions[2, i]
        length = max(np.sqrt(dx * dx + dy * dy + dz * dz), tiny)
        vx, vy, vz = -(dx / length), -(dy / length), -(dz / length)
        nx = b0 * table[N, f] + b1 * table[N + 3, f] + b2 * table[N + 6, f]
        ny = b0 * table[N + 1, f] + b1 * table[N + 4, f] + b2 * table[N + 7, f]
        nz = b0 * table[N + 2, f] + b1 * table[N + 5, f] + b2 * table[N + 8, f]
        length = max(np.sqrt(nx * nx + ny * ny + nz * nz), tiny)
        nx, ny, nz = nx / length, ny / length, nz / length
        cos_g = table[G, f] * vx + table[G + 1, f] * vy + table[G + 2, f] * vz
        if cos_g < 0:
            nx, ny, nz = -nx, -ny, -nz
        nv = nx * vx + ny * vy + nz * vz
        if nv < small:
            lift = small - nv
            nx, ny, nz = nx + lift * vx, ny + lift * vy, nz + lift * vz
            length = max(np.sqrt(nx * nx + ny * ny + nz * nz), tiny)
            nx, ny, nz = nx / length, ny / length, nz / length
        for c in range(3):
            position[c, i] = b0 * table[P + c, f] + b1 * table[P + 3 + c, f] + b2 * table[P + 6 + c, f]
        normal[0, i], normal[1, i], normal[2, i] = nx, ny, nz
        view[0, i], view[1, i], view[2, i] = vx, vy, vz
        if with_uv:
            uv[0, i] = b0 * table[U, f] + b1 * table[U + 2, f] + b2 * table[U + 4, f]
            uv[1, i] = b0 * table[U + 1, f] + b1 * table[U + 3, f] + b2 * table[U + 5, f]
            footprint[i] = table[S, f] * depth[i] * pixel_angle / max(abs(cos_g), small)


# ------------------------------------------------------------------------------------------------ materials


@dataclass
class SurfaceParams:
    """Per-hit material parameters (M samples): diffuse albedo (3, M) linear (albedo (1 - metallic)), roughness
    (M,), f0 (3, M) or a scalar."""

    albedo: np.ndarray
    roughness: np.ndarray
    f0: np.ndarray | np.float32


def material_params(material: Material, hits: Hits) -> SurfaceParams:
    """One trilinear lookup of the material's maps at the hits, at the mip level of their UV footprint."""
    M = hits.position.shape[1]
    maps = material.maps
    if hits.uv is None or maps.width * maps.height == 1:
        texels = np.repeat(maps.levels[-1].reshape(-1, 1), M, axis=1)
    else:
        texels = maps.sample(hits.uv, maps.lod_of_footprint(hits.footprint))
    albedo = texels[:3]
    rc, mc = material.roughness_channel, material.metallic_channel
    rough = texels[rc] if rc is not None else np.full(M, material.roughness_value, np.float32)
    rough = np.maximum(rough, np.float32(MIN_ROUGHNESS))
    metal = texels[mc] if mc is not None else (
        np.full(M, material.metallic_value, np.float32) if material.metallic_value else None)
    f0 = np.float32(material.f0)
    if metal is not None:
        f0 = f0 + (albedo - f0) * metal
        albedo = albedo * (1 - metal)
    return SurfaceParams(albedo, rough, f0)


# ------------------------------------------------------------------------------------------------ BRDF


def wrap_diffuse(ndotl: np.ndarray, wrap) -> np.ndarray:
    """(3, M) max(0, (n.l + w) / (1 + w)) per channel; Lambert's max(0, n.l) for w = 0."""
    w = np.asarray(wrap, np.float32)[:, None]
    return np.maximum((ndotl[None, :] + w) / (1 + w), np.float32(0))


def ggx_specular(nl: np.ndarray, nv: np.ndarray, nh: np.ndarray, vh: np.ndarray, roughness: np.ndarray,
                 f0) -> np.ndarray:
    """(3, M) (or (1, M) for a scalar f0) pi f_spec (n.l): specular radiance per unit (pi-folded) light intensity,
    from the cosines n.l, n.v, n.h, v.h (M,). f_spec = D Vis F: GGX D = a^2 / (pi ((n.h)^2 (a^2 - 1) + 1)^2),
    height-correlated Smith Vis = 0.5 / (n.l sqrt(n.v^2 (1 - a^2) + a^2) + n.v sqrt(n.l^2 (1 - a^2) + a^2)),
    Schlick's F = f0 + (1 - f0) (1 - v.h)^5; a = roughness^2."""
    a2 = (roughness * roughness) ** 2
    d = nh * nh * (a2 - 1) + 1
    vis = 0.5 / np.maximum(nl * np.sqrt(nv * nv * (1 - a2) + a2) + nv * np.sqrt(nl * nl * (1 - a2) + a2), 1e-7)
    s = a2 / (d * d) * vis * nl           # pi D Vis n.l: D's 1/pi cancels the pi folded into the intensity
    x = 1 - vh
    x2 = x * x
    return s * (f0 + (1 - f0) * (x2 * x2 * x))


def ambient_specular(f0, roughness: np.ndarray, nv: np.ndarray) -> np.ndarray:
    """(3, M) Karis' analytic approximation of the split-sum environment BRDF, F0 A + B, for a uniform
    environment."""
    r0 = roughness * np.float32(-1.0) + np.float32(1.0)
    r1 = roughness * np.float32(-0.0275) + np.float32(0.0425)
    a004 = np.minimum(r0 * r0, np.exp2(np.float32(-9.28) * nv)) * r0 + r1
    A = a004 * np.float32(-1.04) + (roughness * np.float32(-0.572) + np.float32(1.04))
    B = a004 * np.float32(1.04) + (roughness * np.float32(0.022) + np.float32(-0.04))
    return f0 * A + B


# ------------------------------------------------------------------------------------------------ lights


def vertex_albedo(material: Material, uvs: np.ndarray | None, count: int) -> np.ndarray:
    """(N, 3) float32 diffuse albedo (1 - metallic) x albedo at N vertices with uvs (N, 2) (or None), filtered
    over about a 32nd of the texture (the scale at which vertices sample it)."""
    if count == 0:
        return np.zeros((0, 3), np.float32)
    z = np.zeros((3, count), np.float32)
    uv = None if uvs is None else np.ascontiguousarray(np.asarray(uvs, np.float32).T)
    footprint = None if uv is None else np.full(count, 1 / 32, np.float32)
    return np.ascontiguousarray(material_params(material, Hits(z, z, z, uv, footprint)).albedo.T)


def ambient_light(p: SurfaceParams, ambient: np.ndarray, spec, nv: np.ndarray, hits: Hits) -> np.ndarray:
    """(3, M) radiance reflected from the ambient light (3,) and other surfaces: albedo x the indirect irradiance
    (albedo x ambient without it), plus spec x Karis' ambient specular x the open fraction."""
    out = p.albedo * (ambient[:, None] if hits.indirect is None else hits.indirect)
    if spec:
        specular = spec * ambient[:, None] * ambient_specular(p.f0, p.roughness, nv)
        out += specular if hits.visible is None else specular * hits.visible
    return out


def diffuse_model(material: Material, p: SurfaceParams, hits: Hits, skin_model: str):
    """(response(ndl (M,)) -> (3, M) or (M,), reach): a surface's diffuse response per unit irradiance at the
    light's cosine, and the lowest cosine at which it can be lit (below 0: past the terminator; shadow rays are cast
    where the response is not nil)."""
    if material.kind != "skin" or skin_model == "lambert" or (skin_model == "subsurface" and hits.radius is None):
        return (lambda ndl: np.maximum(ndl, 0)), 0.0
    if skin_model == "subsurface":
        width = skin_width(material)
        nails = None if hits.skin is None or hits.skin.all() else np.flatnonzero(~hits.skin)

        def subsurface(ndl):
            out = subsurface_diffuse(ndl, hits.radius, width)
            if nails is not None:
                out[:, nails] = np.maximum(ndl[nails], 0)
            return out
        return subsurface, -1.0
    wrap = np.asarray(material.wrap, np.float32)
    if not wrap.any():
        return (lambda ndl: np.maximum(ndl, 0)), 0.0
    return (lambda ndl: wrap_diffuse(ndl, wrap)), -float(wrap.max())


def shade(material: Material, hits: Hits, lights: list[dict], ambient: np.ndarray, occluded, extent: float,
          counters: dict | None = None, skin_model: str = DEFAULT_SKIN) -> np.ndarray:
    """(3, M) float32 outgoing radiance at the hits.

    lights: world-frame lights (lights.world_lights). occluded(origins (K, 3), directions (K, 3), tfar) -> (K,)
    bool: the scene's occlusion query. extent: the scene's size (m), for the shadow-ray offset. counters: adds
    'shadow_rays'. Indirect light comes with the hits (Hits.indirect, Hits.visible). skin_model: how a skin
    material's diffuse part responds to a light (SKIN_MODELS).
    """
    p = material_params(material, hits)
    n, v = hits.normal, hits.view
    nv = np.clip(_dot(n, v), 1e-4, 1)
    spec = np.float32(material.specular)
    out = ambient_light(p, ambient, spec, nv, hits)
    response, reach = diffuse_model(material, p, hits, skin_model)
    lift = np.float32(SHADOW_LIFT * max(extent, 1e-3))
    for light in lights:
        if light["type"] == "directional":
            l = (-light["direction"]).astype(np.float32)[:, None]
            dist = None
            scale = light["radiance"][:, None]
        else:
            l = light["position"].astype(np.float32)[:, None] - hits.position
            dist = np.sqrt(_dot(l, l))
            l = l / np.maximum(dist, 1e-9)
            scale = light["radiance"][:, None] / np.maximum(dist * dist, 1e-12)
        ndl = _dot(n, l)
        diffuse = response(ndl)
        # Where the diffuse response is nil (and so is the specular, n.l <= 0) no shadow ray is needed.
        reached = ndl > 0 if reach >= 0 else (diffuse.max(axis=0) if diffuse.ndim == 2 else diffuse) > 1e-4
        if light["shadows"]:
            idx = np.flatnonzero(reached)
            if len(idx):
                origin = (hits.position[:, idx] + lift * n[:, idx]).T
                dirs = np.broadcast_to(l.T, (len(idx), 3)) if dist is None else l[:, idx].T
                tfar = np.inf if dist is None else np.maximum(dist[idx] - lift, 0)
                reached[idx[occluded(np.ascontiguousarray(origin), np.ascontiguousarray(dirs), tfar)]] = False
                if counters is not None:
                    counters["shadow_rays"] = counters.get("shadow_rays", 0) + len(idx)
        colour = p.albedo * diffuse
        if spec:
            h = _normalize(v + l)
            colour += spec * ggx_specular(np.clip(ndl, 0, 1), nv, np.clip(_dot(n, h), 0, 1),
                                          np.clip(_dot(v, h), 0, 1), p.roughness, p.f0)
        colour *= reached
        colour *= scale
        out += colour
    return out.astype(np.float32, copy=False)
