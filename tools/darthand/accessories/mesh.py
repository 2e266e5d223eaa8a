"""Accessory geometry: the mesh container and the closed-surface primitives every generator is built from.

Every primitive returns a closed, edge-manifold `Part` (each edge shared by exactly two faces) wound outward, so a
union of disjoint parts is a closed mesh whose inside is well defined (ray parity, signed volume). Generators keep
the parts of one accessory apart by a small gap instead of merging them with booleans.

Frames: an accessory is authored in its local frame, metres: +X the axis it is worn around (a finger bone, the
forearm), +Y the dorsal side (where a watch face or a signet sits), Z = X x Y. `fit` places it on the hand.

UVs follow the OBJ/OpenGL convention: (0, 0) is the bottom-left of the image. Each part's own UVs span [0, 1] and are
mapped into a rectangle of the accessory's texture atlas (`Slot`), so one material with one base-colour and one
metallic-roughness texture describes the whole accessory.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from darthand.model.topology import signed_volume, vertex_normals

# Texture atlas: 2 x 2 slots, each a quarter of the image (u0, v0, u1, v1), inset so filtering does not bleed.
ATLAS_SLOTS = {0: (0.0, 0.5, 0.5, 1.0), 1: (0.5, 0.5, 1.0, 1.0), 2: (0.0, 0.0, 0.5, 0.5), 3: (0.5, 0.0, 1.0, 0.5)}
_INSET = 0.02


@dataclass
class Part:
    """One closed component: vertices (N, 3), faces (F, 3), per-corner uvs (T, 2) in [0, 1] and faces_uv (F, 3);
    `slot` is the atlas slot its UVs go into and `uv_rect` the sub-rectangle of that slot (u0, v0, u1, v1)."""

    vertices: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray
    faces_uv: np.ndarray
    slot: int = 0
    uv_rect: tuple = (0.0, 0.0, 1.0, 1.0)

    def with_uv(self, slot: int | None = None, uv_rect: tuple | None = None) -> "Part":
        return Part(self.vertices, self.faces, self.uvs, self.faces_uv,
                    self.slot if slot is None else slot, self.uv_rect if uv_rect is None else uv_rect)


@dataclass
class AccessoryMesh:
    """A generated accessory in its local frame (metres).

    vertices (N, 3) float64; faces (F, 3) int64, outward; uvs (T, 2) in [0, 1]; faces_uv (F, 3) per-corner indices;
    material: {"kind", "base_color" (linear RGB of the main surface), "metallic", "roughness", ...};
    textures: {"base_color": (H, W, 3) linear float32, "metallic_roughness": (H, W, 3) float32, glTF channel
    layout (G roughness, B metallic)}; dims: real-world dimensions in metres (inner radius, width, ...).
    """

    vertices: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray
    faces_uv: np.ndarray
    material: dict
    textures: dict = field(default_factory=dict)
    dims: dict = field(default_factory=dict)
    part_count: int = 1
    skin: dict | None = None   # gloves only: per-vertex skinning copied from the hand (see generators.glove)

    @property
    def normals(self) -> np.ndarray:
        """(N, 3) area-weighted vertex normals."""
        return vertex_normals(self.vertices, self.faces)


def orient_outward(part: Part) -> Part:
    """Flip a closed part's winding if its signed volume is negative."""
    if signed_volume(part.vertices, part.faces) < 0:
        return Part(part.vertices, part.faces[:, ::-1].copy(), part.uvs, part.faces_uv[:, ::-1].copy(),
                    part.slot, part.uv_rect)
    return part


def combine(parts: list[Part]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Concatenate parts into (vertices, faces, uvs, faces_uv), each part's UVs moved into its atlas rectangle."""
    verts, faces, uvs, fuv = [], [], [], []
    nv = nt = 0
    for p in parts:
        u0, v0, u1, v1 = _atlas_rect(p.slot, p.uv_rect)
        uv = np.clip(p.uvs, 0.0, 1.0)
        verts.append(p.vertices)
        faces.append(p.faces + nv)
        uvs.append(np.stack([u0 + (u1 - u0) * uv[:, 0], v0 + (v1 - v0) * uv[:, 1]], 1))
        fuv.append(p.faces_uv + nt)
        nv += len(p.vertices)
        nt += len(p.uvs)
    return (np.concatenate(verts), np.concatenate(faces).astype(np.int64), np.concatenate(uvs),
            np.concatenate(fuv).astype(np.int64))


def _atlas_rect(slot: int, sub: tuple) -> tuple:
    u0, v0, u1, v1 = ATLAS_SLOTS[slot]
    du, dv = (u1 - u0), (v1 - v0)
    u0, v0, u1, v1 = u0 + _INSET * du, v0 + _INSET * dv, u1 - _INSET * du, v1 - _INSET * dv
    su0, sv0, su1, sv1 = sub
    return (u0 + (u1 - u0) * su0, v0 + (v1 - v0) * sv0, u0 + (u1 - u0) * su1, v0 + (v1 - v0) * sv1)


# ---------------------------------------------------------------- grids
def _grid(n: int, m: int, wrap_n: bool) -> tuple[np.ndarray, np.ndarray]:
    """Faces and per-corner UV faces of an n x m vertex grid, periodic in m (and in n if `wrap_n`).

    Vertex (i, k) is i*m + k; UV (i, k) is i*(m+1) + k on an (n+1 or n) x (m+1) UV grid.
    """
    rows = n if wrap_n else n - 1
    i, k = np.meshgrid(np.arange(rows), np.arange(m), indexing="ij")
    i, k = i.ravel(), k.ravel()
    i1, k1 = (i + 1) % n, (k + 1) % m
    a, b, c, d = i * m + k, i1 * m + k, i1 * m + k1, i * m + k1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    ua, ub, uc, ud = i * (m + 1) + k, (i + 1) * (m + 1) + k, (i + 1) * (m + 1) + k + 1, i * (m + 1) + k + 1
    faces_uv = np.concatenate([np.stack([ua, ub, uc], 1), np.stack([ua, uc, ud], 1)])
    return faces, faces_uv


def _grid_uvs(rows: int, m: int) -> np.ndarray:
    """(rows+1) x (m+1) UV grid: u along the path (rows), v around the profile."""
    u, v = np.meshgrid(np.linspace(0, 1, rows + 1), np.linspace(0, 1, m + 1), indexing="ij")
    return np.stack([u.ravel(), v.ravel()], 1)


# ---------------------------------------------------------------- curves and frames
def ellipse(a: float, b: float, n: int, phase: float = 0.0) -> np.ndarray:
    """(n, 3) points of the ellipse x = 0, y = a cos(t), z = b sin(t), t from `phase`, counter-clockwise about +X."""
    t = phase + 2 * np.pi * np.arange(n) / n
    return np.stack([np.zeros(n), a * np.cos(t), b * np.sin(t)], 1)


def ellipse_normals(a: float, b: float, n: int, phase: float = 0.0) -> np.ndarray:
    """(n, 3) outward unit normals of `ellipse(a, b, n, phase)`."""
    t = phase + 2 * np.pi * np.arange(n) / n
    nrm = np.stack([np.zeros(n), b * np.cos(t), a * np.sin(t)], 1)
    return nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def ellipse_perimeter(a: float, b: float) -> float:
    """Ramanujan's second approximation (relative error below 1e-9 for wrist-like aspect ratios)."""
    h = ((a - b) / (a + b)) ** 2
    return float(np.pi * (a + b) * (1 + 3 * h / (10 + np.sqrt(4 - 3 * h))))


def frames_about_x(path: np.ndarray, closed: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Sweep frames (n1, n2) along a curve that winds about the X axis: n1 is the unit normal in the plane
    perpendicular to the tangent pointing away from the axis side, n2 = n1 x tangent (close to +X)."""
    if closed:
        t = np.roll(path, -1, 0) - np.roll(path, 1, 0)
    else:
        t = np.gradient(path, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    n1 = np.cross(t, [1.0, 0.0, 0.0])
    n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
    n2 = np.cross(n1, t)
    return n1, n2


# ---------------------------------------------------------------- primitives
def sweep(path: np.ndarray, n1: np.ndarray, n2: np.ndarray, profile: np.ndarray, closed: bool = True) -> Part:
    """Sweep a closed 2D profile along a path: vertex (i, k) = path[i] + p[i,k,0] n1[i] + p[i,k,1] n2[i].

    path, n1, n2: (n, 3); profile: (m, 2) or (n, m, 2) to vary it along the path (twist, thickening).
    closed: the path is a loop (a torus-like surface); otherwise the ends are capped with a fan.
    """
    n = len(path)
    prof = np.broadcast_to(profile, (n,) + np.shape(profile)[-2:])
    m = prof.shape[1]
    verts = (path[:, None, :] + prof[..., 0:1] * n1[:, None, :] + prof[..., 1:2] * n2[:, None, :]).reshape(-1, 3)
    faces, faces_uv = _grid(n, m, closed)
    uvs = _grid_uvs(n if closed else n - 1, m)
    if not closed:
        verts, faces, uvs, faces_uv = _cap_ends(verts, faces, uvs, faces_uv, prof, n, m)
    return orient_outward(Part(verts, faces, uvs, faces_uv))


def _cap_ends(verts, faces, uvs, faces_uv, prof, n, m):
    """Close an open sweep with a fan around each end profile's centroid (the profile must be star-shaped)."""
    ends = [np.arange(m), (n - 1) * m + np.arange(m)]
    new_v, new_f, new_uv, new_fuv = [verts], [faces], [uvs], [faces_uv]
    nv, nt = len(verts), len(uvs)
    for e, ring in enumerate(ends):
        new_v.append(verts[ring].mean(0, keepdims=True))
        k = np.arange(m)
        fan = np.stack([np.full(m, nv), ring[k], ring[(k + 1) % m]], 1)   # against the grid's row-0 edges
        new_f.append(fan if e == 0 else fan[:, ::-1])
        p = prof[0 if e == 0 else n - 1]
        q = (p - p.mean(0)) / (2.0 * np.abs(p - p.mean(0)).max() + 1e-12) + 0.5
        new_uv.append(np.concatenate([[[0.5, 0.5]], q]))
        fan_uv = np.stack([np.full(m, nt), nt + 1 + k, nt + 1 + (k + 1) % m], 1)
        new_fuv.append(fan_uv if e == 0 else fan_uv[:, ::-1])
        nv += 1
        nt += m + 1
    return np.concatenate(new_v), np.concatenate(new_f), np.concatenate(new_uv), np.concatenate(new_fuv)


def stacked_solid(footprint: np.ndarray, heights, scales, bottom_apex: float | None = None,
                  top_apex: float | None = None, cap_slot: int | None = None, side_slot: int = 0) -> list[Part]:
    """A solid of scaled copies of a closed, star-shaped 2D footprint stacked along +Z, capped by fans.

    footprint: (m, 2) counter-clockwise about the origin; heights, scales: (L,) levels, bottom to top;
    bottom_apex / top_apex: height of the fan centres (default: the first / last level, a flat cap).
    Returns [sides-and-bottom part, top-cap part]; the top cap's UVs are a planar map of the footprint (a watch
    dial, a gem's table, a signet's face), in atlas slot `cap_slot` (default: `side_slot`).
    All faces share one vertex set per part pair, so the union of the two returned parts is closed.
    """
    fp = np.asarray(footprint, float)
    m, L = len(fp), len(heights)
    rings = np.concatenate([np.column_stack([fp * s, np.full(m, h)]) for h, s in zip(heights, scales)])
    bottom = [0.0, 0.0, heights[0] if bottom_apex is None else bottom_apex]
    top = [0.0, 0.0, heights[-1] if top_apex is None else top_apex]
    verts = np.concatenate([rings, [bottom, top]])
    ib, it = L * m, L * m + 1
    side_f, side_fuv = _grid(L, m, False)
    side_uv = _grid_uvs(L - 1, m)
    k = np.arange(m)
    # Fans run against the neighbouring side faces' edges: the grid's row-0 edges go (k+1) -> k.
    bot_f = np.stack([np.full(m, ib), k, (k + 1) % m], 1)
    bot_uv = np.concatenate([side_uv, [[0.5, 0.0]]])
    bot_fuv = np.stack([np.full(m, len(side_uv)), k, k + 1], 1)  # reuse row 0 UVs
    last = (L - 1) * m
    top_f = np.stack([np.full(m, it), last + (k + 1) % m, last + k], 1)
    extent = np.abs(fp * scales[-1]).max()
    cap_uv = np.concatenate([[[0.5, 0.5]], 0.5 + 0.5 * fp * scales[-1] / extent])
    top_fuv = np.stack([np.zeros(m, int), 1 + (k + 1) % m, 1 + k], 1)
    # Orientation decided on the closed whole, then applied to both parts.
    flip = signed_volume(verts, np.concatenate([side_f, bot_f, top_f])) < 0
    fl = (lambda f: f[:, ::-1].copy()) if flip else (lambda f: f)
    sides = Part(verts, fl(np.concatenate([side_f, bot_f])), bot_uv, fl(np.concatenate([side_fuv, bot_fuv])),
                 side_slot)
    cap = Part(verts, fl(top_f), cap_uv, fl(top_fuv), side_slot if cap_slot is None else cap_slot)
    return [sides, cap]


def merge_shared(parts: list[Part]) -> list[Part]:
    """Parts that share one vertex array (from `stacked_solid`) re-indexed so `combine` does not duplicate it:
    the first part keeps the vertices, the others get empty vertex arrays and faces indexing the first's."""
    first = parts[0]
    n = len(first.vertices)  # `combine` has advanced its vertex offset by n when it reaches the others
    return [first] + [Part(np.zeros((0, 3)), p.faces - n, p.uvs, p.faces_uv, p.slot, p.uv_rect) for p in parts[1:]]


def solid_parts(parts: list[Part], matrix: np.ndarray | None = None) -> list[Part]:
    """`stacked_solid` output moved by a 4x4 transform, ready for `combine` (shared vertices kept once)."""
    if matrix is not None:
        v = parts[0].vertices @ matrix[:3, :3].T + matrix[:3, 3]
        flip = np.linalg.det(matrix[:3, :3]) < 0
        parts = [Part(v, p.faces[:, ::-1].copy() if flip else p.faces, p.uvs,
                      p.faces_uv[:, ::-1].copy() if flip else p.faces_uv, p.slot, p.uv_rect) for p in parts]
    return merge_shared(parts)


# ---------------------------------------------------------------- footprints and profiles
def circle2d(r: float, m: int) -> np.ndarray:
    t = 2 * np.pi * np.arange(m) / m
    return np.stack([r * np.cos(t), r * np.sin(t)], 1)


def superellipse2d(a: float, b: float, m: int, power: float = 4.0) -> np.ndarray:
    """|x/a|^p + |y/b|^p = 1, counter-clockwise (p = 2 an ellipse, large p a rounded rectangle)."""
    t = 2 * np.pi * np.arange(m) / m
    c, s = np.cos(t), np.sin(t)
    return np.stack([a * np.sign(c) * np.abs(c) ** (2 / power), b * np.sign(s) * np.abs(s) ** (2 / power)], 1)


def rounded_rect2d(n0: float, n1: float, x_half: float, m: int, power: float = 6.0) -> np.ndarray:
    """A band's cross-section: a rounded rectangle spanning n in [n0, n1] (radial) and x in [-x_half, x_half]."""
    p = superellipse2d((n1 - n0) / 2, x_half, m, power)
    return p + [(n0 + n1) / 2, 0.0]


def heart2d(r: float, m: int) -> np.ndarray:
    """A heart outline about the origin, counter-clockwise, about 2r across (star-shaped about the origin)."""
    t = 2 * np.pi * np.arange(m) / m
    x = 16 * np.sin(t) ** 3
    y = 13 * np.cos(t) - 5 * np.cos(2 * t) - 2 * np.cos(3 * t) - np.cos(4 * t)
    p = np.stack([x, y + 2.0], 1) * (r / 17.0)
    return p[::-1] if _area2d(p) < 0 else p


def star2d(r: float, points: int = 5, inner: float = 0.5) -> np.ndarray:
    t = np.pi * np.arange(2 * points) / points
    rr = np.where(np.arange(2 * points) % 2 == 0, r, r * inner)
    return np.stack([rr * np.sin(t), rr * np.cos(t)], 1)[::-1]


def _area2d(p: np.ndarray) -> float:
    x, y = p[:, 0], p[:, 1]
    return float(0.5 * (x * np.roll(y, -1) - np.roll(x, -1) * y).sum())


def frame_matrix(origin, x_axis, y_axis) -> np.ndarray:
    """4x4 transform whose columns are the unit axes x, y (orthogonalised), z = x cross y, and the origin."""
    x = np.asarray(x_axis, float)
    x = x / np.linalg.norm(x)
    y = np.asarray(y_axis, float) - np.dot(y_axis, x) * x
    y = y / np.linalg.norm(y)
    M = np.eye(4)
    M[:3, 0], M[:3, 1], M[:3, 2], M[:3, 3] = x, y, np.cross(x, y), origin
    return M
