"""The environment's specular lookups at vertex rate (`ShadingOptions.environment_lookups` 'vertex').

shade.environment_specular looks the environment's prefiltered remainder up along each sample's reflection
direction: two arctangents for the map coordinates, then a trilinear lookup between the two mip levels whose texels
span the lobe (environment.lookup_blurred_many). At the skin's roughness the lobe is 20 degrees or wider, smooth
over a triangle a few pixels across, so here the bilinear value of each mip level that the batch's lobes need is
looked up once per corner (vertex and side, shadows.ShadowCorners) along the corner's reflection direction (its
unit vertex normal on the side the camera sees, bent into the visible hemisphere as the samples' normals are, and
the direction toward the camera), and each sample blends its face's three corners by its barycentrics at its own
two levels, mixed by its own fractional level (its roughness: textures vary it within a face). Same trilinear
structure, the bilinear lookups moved to the corners; the Fresnel factor and the occlusion stay per sample. Near
a silhouette the reflection swings across the sky within a face: a sample of a face with a corner seen at
n.v < GRAZING is looked up on its own, as per sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darthand.jit import kernel
from darthand.render.environment import lookup_blurred_many, pack_levels
from darthand.render.shadows import ShadowCorners

GRAZING = 0.5           # a face with a corner seen at n.v below this is looked up per sample (silhouettes)

@dataclass
class SpecularCorners:
    """The corners of M hits with what the lookups at their corners need: corners (shadows.ShadowCorners), bu, bv
    (M,) float32 the hits' barycentrics (weights 1 - bu - bv, bu, bv), eye (3,) float64 the camera centre (world)."""

    corners: ShadowCorners
    bu: np.ndarray
    bv: np.ndarray
    eye: np.ndarray


def specular_corners(corners: ShadowCorners, bu: np.ndarray, bv: np.ndarray, eye: np.ndarray) -> SpecularCorners:
    """SpecularCorners of hits with barycentrics bu, bv (M,) on the faces of `corners`, seen from eye (3,)."""
    f32 = lambda a: np.ascontiguousarray(a, np.float32)
    return SpecularCorners(corners, f32(bu), f32(bv), np.asarray(eye, np.float64))


def vertex_specular(environment, at: SpecularCorners, roughness: np.ndarray, normal: np.ndarray,
                    view: np.ndarray) -> np.ndarray:
    """(3, M) float32 the environment's remainder (environment.FrameEnvironment) prefiltered for GGX roughness (M,)
    at the hits of `at`, from lookups at their corners (FrameEnvironment.specular's blur: about 90 alpha degrees);
    hits of faces near a silhouette along their own reflection directions, from their unit normals and views
    (3, M) float32, as FrameEnvironment.specular."""
    slots = at.corners.slots
    m = len(slots)
    if m == 0:
        return np.zeros((3, 0), np.float32)
    slot_index = np.full(len(at.corners.positions) * 2, -1, np.int64)
    corner_of, distinct = np.empty((m, 3), np.int64), np.empty(min(3 * m, len(slot_index)), np.int64)
    n = _distinct_kernel(slots, slot_index, corner_of, distinct)
    reflect, facing = np.empty((n, 3), np.float64), np.empty(n, np.float64)
    _reflect_kernel(distinct[:n], at.corners.positions, at.corners.normals, at.eye, reflect, facing)
    packed = environment.lighting.packed or pack_levels(environment.lighting.remainder)
    top = len(packed.heights) - 1
    finest = 360.0 / (2 * float(packed.heights[0]))
    roughness = np.ascontiguousarray(roughness, np.float32)
    lods = np.clip(np.log2(np.maximum(90.0 * np.array([roughness.min(), roughness.max()], np.float64) ** 2, finest)
                           / finest), 0, top)                # the lod's range (it grows with the roughness)
    first, last = int(lods[0]), min(int(lods[1]) + 1, top)
    level_angles = finest * 2.0 ** np.arange(first, last + 1, dtype=np.float64)             # lod exactly l
    values = lookup_blurred_many(packed, reflect @ environment.M.T, np.repeat(level_angles[:, None], n, axis=1),
                                 environment.scale)
    out, own_reflect, own = np.empty((3, m), np.float32), np.empty((3, m), np.float32), np.empty(m, np.int64)
    k = _blend_kernel(values, first, top, finest, corner_of, at.bu, at.bv, roughness, facing, GRAZING,
                      np.ascontiguousarray(normal, np.float32), np.ascontiguousarray(view, np.float32), out,
                      own_reflect, own)
    if k:
        out[:, own[:k]] = environment.specular(own_reflect[:, :k], roughness[own[:k]])
    return out


@kernel
def _distinct_kernel(slots, slot_index, corner_of, distinct):
    """corner_of[i, c]: the index of slots[i, c] among the distinct slots (distinct: in order of first use;
    slot_index (2V,) -1 in, each used slot's index out). Returns how many are distinct."""
    n = 0
    for i in range(slots.shape[0]):
        for c in range(3):
            s = slots[i, c]
            if slot_index[s] < 0:
                slot_index[s] = n
                distinct[n] = s
                n += 1
            corner_of[i, c] = slot_index[s]
    return n


@kernel(error_model="numpy")
def _reflect_kernel(distinct, positions, normals, eye, reflect, facing):
    """reflect (S, 3) float64: per slot (2 x vertex + side) the direction toward the eye v reflected about the unit
    vertex normal n (negated for side 1; where n.v < 1e-3, n + (1e-3 - n.v) v normalised, as shade's hits bend
    silhouettes), 2 (n.v) n - v; facing (S,) n.v before the bend."""
    tiny, small = 1e-30, 1e-3
    for j in range(distinct.shape[0]):
        s = distinct[j]
        k = s // 2
        vx, vy, vz = eye[0] - positions[k, 0], eye[1] - positions[k, 1], eye[2] - positions[k, 2]
        length = max(np.sqrt(vx * vx + vy * vy + vz * vz), tiny)
        vx, vy, vz = vx / length, vy / length, vz / length
        nx, ny, nz = float(normals[k, 0]), float(normals[k, 1]), float(normals[k, 2])
        length = max(np.sqrt(nx * nx + ny * ny + nz * nz), tiny)
        if s % 2 == 1:
            length = -length
        nx, ny, nz = nx / length, ny / length, nz / length
        nv = nx * vx + ny * vy + nz * vz
        facing[j] = nv
        if nv < small:
            lift = small - nv
            nx, ny, nz = nx + lift * vx, ny + lift * vy, nz + lift * vz
            length = max(np.sqrt(nx * nx + ny * ny + nz * nz), tiny)
            nx, ny, nz = nx / length, ny / length, nz / length
            nv = nx * vx + ny * vy + nz * vz
        reflect[j, 0] = 2 * nv * nx - vx
        reflect[j, 1] = 2 * nv * ny - vy
        reflect[j, 2] = 2 * nv * nz - vz


@kernel(error_model="numpy")
def _blend_kernel(values, first, top, finest, corner_of, bu, bv, roughness, facing, grazing, normal, view, out,
                  own_reflect, own):
    """out (3, M) float32: per hit i, (1 - f) A_lo + f A_lo+1 at its fractional level (lookup_blurred_many's, of
    roughness[i]: lo its integer part, f the rest; lo + 1 only below the top level `top` and where f > 0), A_l the
    barycentric blend (1 - bu - bv, bu, bv) of its corners' (corner_of (M, 3)) values at level l: values (L', 3, S)
    float64, levels first .. first + L' - 1; finest: level 0's texel angle (degrees). A hit with a corner whose
    facing (S,) is below `grazing` is left out: its index appended to own and its reflection direction
    2 (n.v) n - v (normal, view (3, M) float32) to own_reflect (3, M); returns how many."""
    k = 0
    two = np.float32(2.0)
    for i in range(corner_of.shape[0]):
        a, b, c = corner_of[i, 0], corner_of[i, 1], corner_of[i, 2]
        if min(min(facing[a], facing[b]), facing[c]) < grazing:
            nv = normal[0, i] * view[0, i] + normal[1, i] * view[1, i] + normal[2, i] * view[2, i]
            for ch in range(3):                    # float32, as shade.environment_specular's numpy
                own_reflect[ch, k] = two * nv * normal[ch, i] - view[ch, i]
            own[k] = i
            k += 1
            continue
        r = np.float64(roughness[i])
        level = min(max(np.log2(max(90.0 * r * r, finest) / finest), 0.0), np.float64(top))
        lo = min(int(level), top)
        frac = level - lo
        w1, w2 = np.float64(bu[i]), np.float64(bv[i])
        w0 = 1.0 - w1 - w2
        row = lo - first
        for ch in range(3):
            value = (1 - frac) * (w0 * values[row, ch, a] + w1 * values[row, ch, b] + w2 * values[row, ch, c])
            if lo < top and frac > 0:
                value += frac * (w0 * values[row + 1, ch, a] + w1 * values[row + 1, ch, b]
                                 + w2 * values[row + 1, ch, c])
            out[ch, i] = value
    return k
