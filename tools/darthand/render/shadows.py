"""Shadow rays at vertex rate: a light's visibility traced from the corners of the triangles that samples hit, and
per-sample rays only in the triangles whose corners disagree (`ShadingOptions.shadows` 'vertex').

A directional or point light's shadow over a triangle a few pixels wide is, almost everywhere, all lit or all dark:
the shadow's edge crosses few triangles. Tracing one occlusion ray per corner vertex (shared by the ~6 triangles
around it) instead of one per sample, and the per-sample rays of shade.py only where the three corners disagree,
gives the same answer but where an occluder lies between a triangle's corners without touching their rays (a thin
strap, a ring's edge over a large face): benchmarks/render_shadows.py measures how often.

A corner's ray is the per-sample ray's at the vertex: it leaves the vertex lifted along the unit vertex normal (on
the side of the face the camera sees, as the sample's shading normal is turned) by the same offset, toward the
light. Corners are keyed by (vertex, side): a vertex of faces seen from both sides has a ray per side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darthand.jit import inlined, kernel


@dataclass
class ShadowCorners:
    """Where M hits lie on their surface's mesh: slots (M, 3) int64, the hit's face's corners as 2 x vertex + side
    (1 where the camera sees the face's back); positions and normals (V, 3) float32 the surface's world vertices
    and vertex normals."""

    slots: np.ndarray
    positions: np.ndarray
    normals: np.ndarray


def hit_corners(faces: np.ndarray, table: np.ndarray, positions: np.ndarray, normals: np.ndarray, prim: np.ndarray,
                view: np.ndarray) -> ShadowCorners:
    """The corners of hits on faces `prim` (M,) of a surface: faces (F, 3) its vertex indices, table its
    scene.FaceData table (the geometric normal's rows), positions and normals (V, 3) its vertices, view (3, M) the
    unit directions toward the camera (the side a hit sees: G.v < 0 is the back, as shade's hits turn the normal)."""
    slots = np.empty((len(prim), 3), np.int64)
    _slots_kernel(np.ascontiguousarray(faces, np.int64), np.ascontiguousarray(table, np.float32),
                  np.ascontiguousarray(prim, np.int64), np.ascontiguousarray(view, np.float32), slots)
    return ShadowCorners(slots, np.ascontiguousarray(positions, np.float32), np.ascontiguousarray(normals, np.float32))


@kernel
def _slots_kernel(faces, table, prim, view, slots):
    """slots[i, c] = 2 faces[prim[i], c] + (the face's geometric normal (table rows 18..20) . view[:, i] < 0)."""
    zero = np.float32(0.0)
    for i in range(prim.shape[0]):
        f = prim[i]
        back = table[18, f] * view[0, i] + table[19, f] * view[1, i] + table[20, f] * view[2, i] < zero
        for c in range(3):
            slots[i, c] = 2 * faces[f, c] + (1 if back else 0)


def vertex_rate_occlusion(corners: ShadowCorners, ray_hit: np.ndarray, position: np.ndarray, normal: np.ndarray,
                          light: np.ndarray, lift: np.float32, occluded) -> tuple[np.ndarray, int]:
    """(blocked (K,) bool, rays traced) for the K hits ray_hit (K,) that reach one light (shade._lights_kernel's
    list; hits at positions, unit shading normals (3, M) float32): one ray per corner slot of the hits' faces, then
    each hit takes its corners' answer where all three agree and its own ray (sample_rays) where they do not.
    light (8,): its lights.light_table row; lift: the rays' offset along the normal (m); occluded: the scene's
    occlusion query (shade.shade's)."""
    slot_ray = np.full(len(corners.positions) * 2, -1, np.int64)
    k = len(ray_hit)
    most = min(3 * k, len(slot_ray))
    v_origins, v_directions, v_tfar = np.empty((most, 3), np.float32), np.empty((most, 3), np.float32), \
        np.empty(most, np.float32)
    slots = corners.slots
    n = _corner_rays_kernel(slots, np.ascontiguousarray(ray_hit, np.int64), corners.positions, corners.normals,
                            np.ascontiguousarray(light, np.float32), np.float32(lift), slot_ray, v_origins,
                            v_directions, v_tfar)
    corner_blocked = occluded(v_origins[:n], v_directions[:n], v_tfar[:n]) if n else np.zeros(0, bool)
    blocked, split = np.empty(k, np.bool_), np.empty(k, np.int64)
    m = _corner_answers_kernel(slots, np.ascontiguousarray(ray_hit, np.int64), slot_ray,
                               np.ascontiguousarray(corner_blocked, np.bool_), blocked, split)
    own = split[:m]
    if m:
        blocked[own] = occluded(*sample_rays(position, normal, ray_hit[own], light, lift))
    return blocked, n + m


def sample_rays(position: np.ndarray, normal: np.ndarray, hit: np.ndarray, light: np.ndarray,
                lift: np.float32) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(origins (K, 3), directions (K, 3), tfar (K,)) float32: the shadow rays of hits `hit` (K,) toward a light
    (its light_table row), the numbers shade._lights_kernel makes: origin p + lift n, direction toward the light,
    tfar inf or the point light's distance less lift."""
    k = len(hit)
    origins, directions, tfar = np.empty((k, 3), np.float32), np.empty((k, 3), np.float32), np.empty(k, np.float32)
    _sample_rays_kernel(position, normal, np.ascontiguousarray(hit, np.int64), np.ascontiguousarray(light, np.float32),
                        np.float32(lift), origins, directions, tfar)
    return origins, directions, tfar


@inlined
def toward_light(x, y, z, light, lift):
    """(dx, dy, dz, tfar) float32 of a shadow ray from the surface point (x, y, z) float32 to a light (its
    lights.light_table row): a point light's unit direction and distance less `lift`, or a directional light's
    direction and inf; in shade._lights_kernel's float32 operations and order."""
    if light[0] != np.float32(0.0):
        lx, ly, lz = light[1] - x, light[2] - y, light[3] - z
        dist = np.sqrt(lx * lx + ly * ly + lz * lz)
        d = max(dist, np.float32(1e-9))
        return lx / d, ly / d, lz / d, max(dist - lift, np.float32(0.0))
    return light[1], light[2], light[3], np.float32(np.inf)


@kernel(error_model="numpy")
def _sample_rays_kernel(position, normal, hit, light, lift, origins, directions, tfar):
    """sample_rays' rays, in _lights_kernel's float32 operations and order."""
    for r in range(hit.shape[0]):
        i = hit[r]
        origins[r, 0] = position[0, i] + lift * normal[0, i]
        origins[r, 1] = position[1, i] + lift * normal[1, i]
        origins[r, 2] = position[2, i] + lift * normal[2, i]
        directions[r, 0], directions[r, 1], directions[r, 2], tfar[r] = toward_light(
            position[0, i], position[1, i], position[2, i], light, lift)


@kernel(error_model="numpy")
def _corner_rays_kernel(slots, ray_hit, positions, normals, light, lift, slot_ray, origins, directions, tfar):
    """A ray per distinct corner slot of the hits ray_hit (K,) (slots (M, 3)), in order of first use: slot_ray
    (2V,) -1 in, the slot's ray index out; origin the vertex + lift x its unit normal (negated for side 1),
    direction toward the light (light: a light_table row), tfar inf, or the point light's distance less lift (the
    per-sample rays' float32 formulas). Returns how many."""
    r = 0
    for j in range(ray_hit.shape[0]):
        i = ray_hit[j]
        for c in range(3):
            s = slots[i, c]
            if slot_ray[s] >= 0:
                continue
            v = s // 2
            nx, ny, nz = normals[v, 0], normals[v, 1], normals[v, 2]
            length = max(np.sqrt(nx * nx + ny * ny + nz * nz), np.float32(1e-30))
            if s % 2 == 1:
                length = -length
            ox = positions[v, 0] + lift * (nx / length)
            oy = positions[v, 1] + lift * (ny / length)
            oz = positions[v, 2] + lift * (nz / length)
            origins[r, 0], origins[r, 1], origins[r, 2] = ox, oy, oz
            directions[r, 0], directions[r, 1], directions[r, 2], tfar[r] = toward_light(
                positions[v, 0], positions[v, 1], positions[v, 2], light, lift)
            slot_ray[s] = r
            r += 1
    return r


@kernel
def _corner_answers_kernel(slots, ray_hit, slot_ray, corner_blocked, blocked, split):
    """Per sample ray j: blocked[j] its three corners' answer where they agree; where they do not, j is appended to
    split (its own ray decides). Returns how many were split."""
    m = 0
    for j in range(ray_hit.shape[0]):
        i = ray_hit[j]
        a = corner_blocked[slot_ray[slots[i, 0]]]
        b = corner_blocked[slot_ray[slots[i, 1]]]
        c = corner_blocked[slot_ray[slots[i, 2]]]
        blocked[j] = a
        if a != b or a != c:
            split[m] = j
            m += 1
    return m
