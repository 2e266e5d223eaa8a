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
  lighting just past the terminator is not cut off by the surface's own facets. With hits' corners
  (`ShadingOptions.shadows` 'vertex') a light's rays are traced from the vertices of the faces hit, and per sample
  only in faces whose corners disagree (shadows.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darthand.errors import InputError
from darthand.jit import kernel
from darthand.render.lights import light_table
from darthand.render.shadows import ShadowCorners, vertex_rate_occlusion
from darthand.render.skin import skin_width, sphere_blend_table, table_rows
from darthand.render.skin_specular import SKIN_SPECULAR, skin_specular_radiance
from darthand.render.subject import Material

SHADOW_LIFT = 2e-3          # shadow-ray origin offset, relative to the scene's bounding-box diagonal
MIN_ROUGHNESS = 0.045       # GGX is singular at alpha = 0
DEFAULT_AO_RAYS = 16        # ambient-occlusion rays per vertex (benchmarks/render_reference.py: speed against error)
SKIN_MODELS = ("subsurface", "wrap", "lambert")
# scene.FaceData's POSITION, NORMAL, GEOMETRIC, UV, UV_SCALE rows, as _hits_kernel reads them
FACE_ROWS = (0, 9, 18, 21, 27)
DEFAULT_SKIN = "subsurface"
SHADOW_MODES = ("pixel", "vertex")      # ShadingOptions.shadows: a ray per sample, or per vertex (shadows.py)


@dataclass(frozen=True)
class ShadingOptions:
    """How a frame is shaded beyond the direct lights (indirect.py): ao_rays, rays per vertex for the ambient light's
    occlusion and the interreflected light (0: ambient light is never blocked, nothing is interreflected);
    interreflection, add light reflected between surfaces (False: ambient occlusion only); skin, the skin's diffuse
    model (SKIN_MODELS: 'subsurface', 'wrap' the earlier look, 'lambert'); skin_specular, the skin's specular
    response ('single': one GGX lobe; 'dual': two lobes and a sheen, skin_specular.py); skin_detail, the strength of
    the skin's fine relief on its shading normal (skin_detail.py; 0: none, 1: nominal depths); shadows, how the
    lights' shadow rays are traced (SHADOW_MODES: 'pixel' one per sample; 'vertex' one per vertex of the faces
    hit and per sample only where a face's corners disagree, shadows.py). to_json lists skin_specular, skin_detail
    and shadows only when they differ from their defaults (records made before them stay)."""

    ao_rays: int = DEFAULT_AO_RAYS
    interreflection: bool = True
    skin: str = DEFAULT_SKIN
    skin_specular: str = "single"
    skin_detail: float = 0.0
    shadows: str = "pixel"

    def __post_init__(self):
        if isinstance(self.ao_rays, bool) or not (isinstance(self.ao_rays, (int, np.integer))
                                                  and 0 <= self.ao_rays <= 4096):
            raise InputError(f"ao_rays: {self.ao_rays!r} is not a whole number of rays in 0..4096")
        if not isinstance(self.interreflection, (bool, np.bool_)):
            raise InputError(f"interreflection: {self.interreflection!r} is not true or false")
        if self.skin not in SKIN_MODELS:
            raise InputError(f"skin: {self.skin!r} is not one of {', '.join(SKIN_MODELS)}")
        if self.skin_specular not in SKIN_SPECULAR:
            raise InputError(f"skin_specular: {self.skin_specular!r} is not one of {', '.join(SKIN_SPECULAR)}")
        if isinstance(self.skin_detail, bool) or not (isinstance(self.skin_detail, (int, float, np.number))
                                                      and 0 <= self.skin_detail <= 4):
            raise InputError(f"skin_detail: {self.skin_detail!r} is not a number in 0..4")
        if self.shadows not in SHADOW_MODES:
            raise InputError(f"shadows: {self.shadows!r} is not one of {', '.join(SHADOW_MODES)}")

    def to_json(self) -> dict:
        out = {"ao_rays": int(self.ao_rays), "interreflection": bool(self.interreflection), "skin": self.skin}
        if self.skin_specular != "single":
            out["skin_specular"] = self.skin_specular
        if self.skin_detail:
            out["skin_detail"] = float(self.skin_detail)
        if self.shadows != "pixel":
            out["shadows"] = self.shadows
        return out


@dataclass
class Hits:
    """Surface attributes at M ray hits on one surface, float32, component-major: position, normal (shading, facing
    the viewer), view (unit, toward the camera) (3, M); uv (2, M) or None; footprint (M,) the longer side of the
    sample's footprint in uv units, or None; indirect (3, M) the indirect irradiance and visible (M,) the ambient
    light's open fraction (indirect.VertexLight.at), or None (the ambient light reaches everything unblocked);
    radius (M,) the surface's curvature radius (skin.surface_radius) and skin (M,) bool, not a nail, for the
    subsurface skin model, or None; region (M,) the face labels (model.layout.FACE_LABELS, -1 unlabelled) for
    skin's dual-lobe specular, or None; corners the hits' mesh corners (shadows.ShadowCorners) for shadow rays at
    vertex rate (ShadingOptions.shadows 'vertex'), or None: a shadow ray per hit."""

    position: np.ndarray
    normal: np.ndarray
    view: np.ndarray
    uv: np.ndarray | None
    footprint: np.ndarray | None
    indirect: np.ndarray | None = None
    visible: np.ndarray | None = None
    radius: np.ndarray | None = None
    skin: np.ndarray | None = None
    region: np.ndarray | None = None
    corners: ShadowCorners | None = None


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
        assert hits.footprint is not None, "hits with UVs carry their footprint"
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
    (albedo x ambient without it), plus spec x Karis' ambient specular x the open fraction. The definition in numpy;
    `shade` computes the same inside _radiance_kernel."""
    out = p.albedo * (ambient[:, None] if hits.indirect is None else hits.indirect)
    if spec:
        specular = spec * ambient[:, None] * ambient_specular(p.f0, p.roughness, nv)
        out += specular if hits.visible is None else specular * hits.visible
    return out


LAMBERT, WRAP, SUBSURFACE = 0, 1, 2      # _lights_kernel's diffuse models


@dataclass
class DiffuseModel:
    """How a surface's diffuse part responds to a light, as _lights_kernel reads it: kind (LAMBERT: max(0, n.l);
    WRAP: wrap_diffuse with `wrap` (3,); SUBSURFACE: skin.subsurface_diffuse, its table rows from skin.table_rows
    (row_r (M,), shifts (3,)), Lambert where `skin` (M,) bool is False (nails; empty: all skin)); by_cosine: a light
    reaches where n.l > 0 (else: where the response's largest channel exceeds 1e-4, past the terminator)."""

    kind: int
    by_cosine: bool
    wrap: np.ndarray
    row_r: np.ndarray
    shifts: np.ndarray
    skin: np.ndarray


def diffuse_model(material: Material, hits: Hits, skin_model: str) -> DiffuseModel:
    """The diffuse response of `material` at `hits` under the skin model `skin_model` (SKIN_MODELS): Lambert for
    every material but skin (and for skin without its curvature radius under 'subsurface', or an all-zero wrap)."""
    none = np.zeros(0, np.float32)
    lambert = DiffuseModel(LAMBERT, True, np.zeros(3, np.float32), none, np.zeros(3, np.float32), np.zeros(0, bool))
    if material.kind != "skin" or skin_model == "lambert" or (skin_model == "subsurface" and hits.radius is None):
        return lambert
    if skin_model == "subsurface":
        row_r, shifts = table_rows(np.ascontiguousarray(hits.radius, np.float32), skin_width(material))
        skin = np.zeros(0, bool) if hits.skin is None else np.ascontiguousarray(hits.skin, bool)
        return DiffuseModel(SUBSURFACE, False, lambert.wrap, np.ascontiguousarray(row_r, np.float32), shifts, skin)
    wrap = np.asarray(material.wrap, np.float32)
    if not wrap.any():
        return lambert
    return DiffuseModel(WRAP, bool(wrap.max() <= 0), wrap, none, lambert.shifts, lambert.skin)


def shade(material: Material, hits: Hits, lights: list[dict], ambient: np.ndarray, occluded, extent: float,
          counters: dict | None = None, skin_model: str = DEFAULT_SKIN, environment=None,
          skin_specular: str = "single") -> np.ndarray:
    """(3, M) float32 outgoing radiance at the hits.

    lights: world-frame lights (lights.world_lights; radiance float32). occluded(origins (K, 3), directions (K, 3),
    tfar (K,)) -> (K,) bool: the scene's occlusion query. extent: the scene's size (m), for the shadow-ray offset.
    counters: adds 'shadow_rays'. Indirect light comes with the hits (Hits.indirect, Hits.visible). skin_model: how
    a skin material's diffuse part responds to a light (SKIN_MODELS). environment: the frame's
    environment.FrameEnvironment or None; its specular ambient (`environment_specular`) is added. skin_specular:
    'dual' gives a skin material skin_specular.py's lobes and sheen in place of the single lobe (which the kernels
    then leave out).

    Two compiled passes around the shadow rays: _lights_kernel (per light and hit: n.l, the diffuse response, which
    hits the light can reach and their shadow rays), then Embree's occlusion query per light, then _radiance_kernel
    (the ambient term plus each reached light's albedo x diffuse + specular, scaled). Same float32 arithmetic, in the
    same order, as the numpy formulas (ambient_light, wrap_diffuse, skin.subsurface_diffuse, ggx_specular): the
    tests hold them equal; the one libm call (exp2, in ambient_specular) stays numpy's, between the kernels.
    """
    p = material_params(material, hits)
    f32 = lambda a: np.ascontiguousarray(a, np.float32)
    m = hits.position.shape[1]
    n, v, position = f32(hits.normal), f32(hits.view), f32(hits.position)
    table = light_table(lights)
    model = diffuse_model(material, hits, skin_model)
    dual = skin_specular == "dual" and material.kind == "skin"
    spec = np.float32(0.0 if dual else material.specular)
    lift = np.float32(SHADOW_LIFT * max(extent, 1e-3))
    rays = int(table[:, 7].sum()) * m
    nv, e2 = np.empty(m, np.float32), np.empty(m, np.float32)
    diffuse, reached = np.empty((len(lights), 3, m), np.float32), np.empty((len(lights), m), np.bool_)
    made = 0 if hits.corners is not None else rays          # at vertex rate the rays are made where needed
    origins, directions = np.empty((made, 3), np.float32), np.empty((made, 3), np.float32)
    tfar, ray_hit, offsets = np.empty(made, np.float32), np.empty(rays, np.int64), np.zeros(len(lights) + 1, np.int64)
    _lights_kernel(n, v, position, table, model.kind, model.by_cosine, model.wrap, model.row_r, model.shifts,
                   model.skin, sphere_blend_table(), lift, nv, e2, diffuse, reached, origins, directions, tfar,
                   ray_hit, offsets)
    if spec:
        np.exp2(e2, out=e2)                # numpy's exp2 (SIMD): numba's libm differs from it in the last bit
    for k in range(len(lights)):
        a, b = offsets[k], offsets[k + 1]
        if b > a:
            if hits.corners is None:
                blocked, traced = occluded(origins[a:b], directions[a:b], tfar[a:b]), b - a
            else:
                blocked, traced = vertex_rate_occlusion(hits.corners, ray_hit[a:b], position, n, table[k], lift,
                                                        occluded)
            reached[k, ray_hit[a:b][blocked]] = False
            if counters is not None:
                counters["shadow_rays"] = counters.get("shadow_rays", 0) + int(traced)
    # absent inputs as their neutral values, the same numbers: f0 per hit, the ambient light as irradiance, x 1
    f0 = f32(np.broadcast_to(p.f0, (3, m)))
    ambient = f32(ambient)
    irradiance = f32(np.broadcast_to(ambient[:, None], (3, m)) if hits.indirect is None else hits.indirect)
    visible = np.ones(m, np.float32) if hits.visible is None else f32(hits.visible)
    out = np.empty((3, m), np.float32)
    kept = m if environment is not None and spec else 0
    karis, reflect = np.empty((3, kept), np.float32), np.empty((3, kept), np.float64)
    _radiance_kernel(f32(p.albedo), f32(p.roughness), f0, spec, ambient, irradiance, visible, nv, e2, n, v,
                     position, table, diffuse, reached, karis, reflect, out)
    if environment is not None and spec:
        out += spec * environment_specular(environment, p, reflect, karis) * visible
    if dual and material.specular:
        out += skin_specular_radiance(hits, p.roughness, p.f0, float(material.specular), table, reached, ambient,
                                      material.roughness_channel is not None, environment)
    return out


def environment_specular(environment, p: SurfaceParams, reflect: np.ndarray, karis: np.ndarray) -> np.ndarray:
    """(3, M) float32 the specular ambient term of an environment (environment.FrameEnvironment): its radiance
    prefiltered for the hits' roughness along the reflection directions (3, M) float64 (2 (n.v) n - v of the unit
    normals and views, in float32), times Karis' F0 A + B (3, M) float32 (ambient_specular at the kernels' clipped
    n.v); _radiance_kernel leaves both."""
    return environment.specular(reflect, p.roughness) * karis


@kernel(error_model="numpy")
def _lights_kernel(normal, view, position, lights, kind, by_cosine, wrap, row_r, shifts, skin, sphere, lift,
                   nv, e2, diffuse, reached, origins, directions, tfar, ray_hit, offsets):
    """Per hit i: nv[i] = clip(n.v, 1e-4, 1) and e2[i] = -9.28 nv (the exponent of ambient_specular's exp2); per
    light k (row of `lights`, lights.light_table) and hit: the diffuse response diffuse[k, :, i] at n.l (DiffuseModel's
    kind, wrap, row_r, shifts, skin; `sphere` skin.sphere_blend_table), reached[k, i], and for a light
    with shadows a shadow ray per reached hit: origin p + lift n, direction toward the light, tfar (inf, or the
    distance to a point light less lift), ray_hit its hit; light k's rays are [offsets[k], offsets[k + 1]). With
    origins, directions and tfar empty, only ray_hit and offsets (shadows.sample_rays makes the rays it needs).
    Float32 in the numpy formulas' order (subsurface's blend in float64, rounded once, as numpy promotes it)."""
    zero, one, tiny, floor = np.float32(0.0), np.float32(1.0), np.float32(1e-9), np.float32(1e-4)
    cos_half = np.float32(64.0)          # (skin.COS_STEPS - 1) / 2 (literals: a cached kernel would not see a
    cos_last, row_last, row_len = 127, np.float32(48.0), 129   # changed global); rows 0..RATIO_STEPS - 1
    m = normal.shape[1]
    subsurface = kind == 2
    # per hit: n.v, and the subsurface table's row (start index) per channel; nail[i]: Lambert instead
    rows = np.empty((3, m if subsurface else 0), np.int64)
    nail = np.zeros(m if subsurface else 0, np.bool_)
    all_skin = skin.shape[0] == 0
    for i in range(m):
        c = normal[0, i] * view[0, i] + normal[1, i] * view[1, i] + normal[2, i] * view[2, i]
        c = min(max(c, floor), one)
        nv[i] = c
        e2[i] = np.float32(-9.28) * c
    if subsurface:
        for i in range(m):
            for ch in range(3):
                rows[ch, i] = np.int64(min(max(np.rint(row_r[i] + shifts[ch]), zero), row_last)) * row_len
            nail[i] = not (all_skin or skin[i])
    w0, w1, w2 = wrap[0], wrap[1], wrap[2]
    u0, u1, u2 = one + w0, one + w1, one + w2
    toward = np.empty((4, m), np.float32)          # a point light's direction and distance per hit
    with_rays = origins.shape[0] > 0
    ndl = np.empty(m, np.float32)
    r = 0
    # loops of straight-line code, one per case (LLVM vectorises them), then the rays' compaction
    for k in range(lights.shape[0]):
        point = lights[k, 0] != zero
        px, py, pz = lights[k, 1], lights[k, 2], lights[k, 3]
        if point:
            for i in range(m):
                lx, ly, lz = px - position[0, i], py - position[1, i], pz - position[2, i]
                dist = np.sqrt(lx * lx + ly * ly + lz * lz)
                d = max(dist, tiny)
                lx, ly, lz = lx / d, ly / d, lz / d
                toward[0, i], toward[1, i], toward[2, i], toward[3, i] = lx, ly, lz, dist
                ndl[i] = normal[0, i] * lx + normal[1, i] * ly + normal[2, i] * lz
        else:
            for i in range(m):
                ndl[i] = normal[0, i] * px + normal[1, i] * py + normal[2, i] * pz
        if kind == 1:
            for i in range(m):
                d0 = max((ndl[i] + w0) / u0, zero)
                d1 = max((ndl[i] + w1) / u1, zero)
                d2 = max((ndl[i] + w2) / u2, zero)
                diffuse[k, 0, i], diffuse[k, 1, i], diffuse[k, 2, i] = d0, d1, d2
                reached[k, i] = ndl[i] > zero if by_cosine else max(max(d0, d1), d2) > floor
        elif subsurface:
            for i in range(m):
                cu = (min(max(ndl[i], -one), one) + one) * cos_half
                c0 = min(np.int64(cu), cos_last)
                fc = np.float64(cu) - np.float64(c0)
                f = rows[0, i] + c0
                d0 = np.float32(sphere[f, 0] + fc * sphere[f, 1])
                f = rows[1, i] + c0
                d1 = np.float32(sphere[f, 0] + fc * sphere[f, 1])
                f = rows[2, i] + c0
                d2 = np.float32(sphere[f, 0] + fc * sphere[f, 1])
                lam = max(ndl[i], zero)
                if nail[i]:
                    d0 = d1 = d2 = lam
                diffuse[k, 0, i], diffuse[k, 1, i], diffuse[k, 2, i] = d0, d1, d2
                reached[k, i] = max(max(d0, d1), d2) > floor
        else:
            for i in range(m):
                lam = max(ndl[i], zero)
                diffuse[k, 0, i], diffuse[k, 1, i], diffuse[k, 2, i] = lam, lam, lam
                reached[k, i] = ndl[i] > zero
        offsets[k] = r
        if lights[k, 7] == zero:
            continue
        for i in range(m):                         # the shadow rays of the reached hits, in order
            if reached[k, i]:
                if with_rays:
                    origins[r, 0] = position[0, i] + lift * normal[0, i]
                    origins[r, 1] = position[1, i] + lift * normal[1, i]
                    origins[r, 2] = position[2, i] + lift * normal[2, i]
                    if point:
                        directions[r, 0], directions[r, 1], directions[r, 2] = toward[0, i], toward[1, i], toward[2, i]
                        tfar[r] = max(toward[3, i] - lift, zero)
                    else:
                        directions[r, 0], directions[r, 1], directions[r, 2] = px, py, pz
                        tfar[r] = np.float32(np.inf)
                ray_hit[r] = i
                r += 1
    offsets[lights.shape[0]] = r


@kernel(error_model="numpy")
def _radiance_kernel(albedo, roughness, f0, spec, ambient, irradiance, visible, nv, e2, normal, view, position,
                     lights, diffuse, reached, karis, reflect, out):
    """out (3, M): per hit, ambient_light (albedo x irradiance (3, M) (the indirect irradiance, or the ambient
    light), plus spec x ambient (3,) x Karis' F0 A + B x visible (M,), e2 = exp2(-9.28 n.v)), then per reached light
    (lights, diffuse, reached as _lights_kernel left them) albedo x diffuse + spec x ggx_specular, times its radiance
    (over the squared distance for a point light). f0 (3, M). Float32 in the numpy formulas' order. karis (3, M)
    float32 and reflect (3, M) float64, or (3, 0) for none: F0 A + B and the reflection direction 2 (n.v) n - v
    (float32, unclipped n.v summed x, y, z, as numpy's sum over axis 0) are left there (environment_specular's)."""
    zero, one, half = np.float32(0.0), np.float32(1.0), np.float32(0.5)
    tiny, eps = np.float32(1e-30), np.float32(1e-7)
    m = albedo.shape[1]
    with_spec = spec != zero
    keep = karis.shape[1] == m
    s0, s1, s2 = spec * ambient[0], spec * ambient[1], spec * ambient[2]
    for i in range(m):
        o0, o1, o2 = albedo[0, i] * irradiance[0, i], albedo[1, i] * irradiance[1, i], albedo[2, i] * irradiance[2, i]
        if with_spec:
            rough = roughness[i]
            r0 = rough * np.float32(-1.0) + one
            r1 = rough * np.float32(-0.0275) + np.float32(0.0425)
            a004 = min(r0 * r0, e2[i]) * r0 + r1
            A = a004 * np.float32(-1.04) + (rough * np.float32(-0.572) + np.float32(1.04))
            B = a004 * np.float32(1.04) + (rough * np.float32(0.022) + np.float32(-0.04))
            k0, k1, k2 = f0[0, i] * A + B, f0[1, i] * A + B, f0[2, i] * A + B
            o0 = o0 + s0 * k0 * visible[i]
            o1 = o1 + s1 * k1 * visible[i]
            o2 = o2 + s2 * k2 * visible[i]
            if keep:
                karis[0, i], karis[1, i], karis[2, i] = k0, k1, k2
                twice = np.float32(2) * (normal[0, i] * view[0, i] + normal[1, i] * view[1, i]
                                         + normal[2, i] * view[2, i])
                reflect[0, i] = twice * normal[0, i] - view[0, i]
                reflect[1, i] = twice * normal[1, i] - view[1, i]
                reflect[2, i] = twice * normal[2, i] - view[2, i]
        out[0, i], out[1, i], out[2, i] = o0, o1, o2
    for k in range(lights.shape[0]):
        point = lights[k, 0] != zero
        px, py, pz = lights[k, 1], lights[k, 2], lights[k, 3]
        e0, e1, e2_ = lights[k, 4], lights[k, 5], lights[k, 6]
        for i in range(m):
            if not reached[k, i]:
                continue                 # numpy's colour x 0 added: the same sum
            lx, ly, lz = px, py, pz
            q0, q1, q2 = e0, e1, e2_
            if point:
                lx, ly, lz = lx - position[0, i], ly - position[1, i], lz - position[2, i]
                dist = np.sqrt(lx * lx + ly * ly + lz * lz)
                d = max(dist, np.float32(1e-9))
                lx, ly, lz = lx / d, ly / d, lz / d
                falloff = max(dist * dist, np.float32(1e-12))
                q0, q1, q2 = e0 / falloff, e1 / falloff, e2_ / falloff
            c0 = albedo[0, i] * diffuse[k, 0, i]
            c1 = albedo[1, i] * diffuse[k, 1, i]
            c2 = albedo[2, i] * diffuse[k, 2, i]
            if with_spec:
                nx, ny, nz = normal[0, i], normal[1, i], normal[2, i]
                vx, vy, vz = view[0, i], view[1, i], view[2, i]
                nvi = nv[i]
                a2 = roughness[i] * roughness[i]
                a2 = a2 * a2
                ndl = nx * lx + ny * ly + nz * lz
                hx, hy, hz = vx + lx, vy + ly, vz + lz
                length = max(np.sqrt(hx * hx + hy * hy + hz * hz), tiny)
                hx, hy, hz = hx / length, hy / length, hz / length
                nl = min(max(ndl, zero), one)
                nh = min(max(nx * hx + ny * hy + nz * hz, zero), one)
                vh = min(max(vx * hx + vy * hy + vz * hz, zero), one)
                d = nh * nh * (a2 - one) + one
                vis = half / max(nl * np.sqrt(nvi * nvi * (one - a2) + a2) + nvi * np.sqrt(nl * nl * (one - a2) + a2),
                                 eps)
                s = a2 / (d * d) * vis * nl
                x = one - vh
                x2 = x * x
                x5 = x2 * x2 * x
                c0 = c0 + spec * (s * (f0[0, i] + (one - f0[0, i]) * x5))
                c1 = c1 + spec * (s * (f0[1, i] + (one - f0[1, i]) * x5))
                c2 = c2 + spec * (s * (f0[2, i] + (one - f0[2, i]) * x5))
            out[0, i] = out[0, i] + c0 * q0
            out[1, i] = out[1, i] + c1 * q1
            out[2, i] = out[2, i] + c2 * q2
