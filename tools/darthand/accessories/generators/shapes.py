"""Shapes shared by the generators, all wound about the local X axis around an elliptical bore.

The bore is the ellipse y = a cos t, z = b sin t in the plane x = x0 (a circle for rings). Every shape keeps its
inner surface on or outside the bore, so the fitted bore is exactly the accessory's inner size. t = 0 is the
dorsal side (+Y).
"""

from __future__ import annotations

import numpy as np

from darthand.accessories.mesh import (Part, circle2d, ellipse, ellipse_normals, ellipse_perimeter, frame_matrix,
                                       frames_about_x, solid_parts, stacked_solid, superellipse2d, sweep)

X = np.array([1.0, 0.0, 0.0])


def samples_for(length: float, spacing: float = 0.0015, minimum: int = 48) -> int:
    """Path samples for a curve of `length` metres at about `spacing` (even, for symmetric tessellation)."""
    n = max(minimum, int(np.ceil(length / spacing)))
    return n + n % 2


def band(a: float, b: float, profile: np.ndarray, n: int | None = None, x0: float = 0.0) -> Part:
    """A closed band: a profile (m, 2) or (n, m, 2) in (outward n >= 0, axial x) swept around the bore."""
    n = n or samples_for(ellipse_perimeter(a, b))
    path = ellipse(a, b, n) + [x0, 0, 0]
    return sweep(path, ellipse_normals(a, b, n), np.tile(X, (n, 1)), profile)


def rope(a: float, b: float, strands: int, twists: int, strand_radius: float, spread: float,
         n: int | None = None, m: int = 10) -> list[Part]:
    """`strands` tubes twisted about a core curve that runs `spread + strand_radius` outside the bore.

    Strand j's centre is core + spread (cos s_j n1 + sin s_j x), s_j = twists * t + 2 pi j / strands; the
    closest a strand gets to the bore is 0 (when cos s_j = -1). Strands stay apart while
    2 spread sin(pi / strands) > 2 strand_radius.
    """
    n = n or samples_for(ellipse_perimeter(a, b) * 2, 0.001, 96)
    t = 2 * np.pi * np.arange(n) / n
    base, nrm = ellipse(a, b, n), ellipse_normals(a, b, n)
    core = spread + strand_radius
    parts = []
    for j in range(strands):
        s = twists * t + 2 * np.pi * j / strands
        path = base + (core + spread * np.cos(s))[:, None] * nrm + (spread * np.sin(s))[:, None] * X
        n1, n2 = frames_about_x(path)
        parts.append(sweep(path, n1, n2, circle2d(strand_radius, m)))
    return parts


def chain(a: float, b: float, wire: float, slot: int = 0) -> tuple[list[Part], np.ndarray, np.ndarray]:
    """A cable chain of interlocking oval links around the bore; returns (parts, link centres, link tangents).

    Link: a stadium of centreline half-length L = 5 w and half-width H = 3.3 w swept with a wire of radius w;
    links alternate between lying flat (plane of tangent and X) and standing (plane of tangent and normal).
    With pitch p in (L + w, 2L - 2w) neighbours interlock without touching and next-but-one links stay apart;
    the link count is even so the alternation closes.
    """
    L, H = 5.0 * wire, 3.3 * wire
    core = H + wire                                        # standing links just clear the bore
    count = int(round(offset_perimeter(a, b, core) / (7.0 * wire)))
    count += count % 2
    pts, tangents, normals = arc_length_frames(a, b, count, core)
    stadium = _stadium(L, H, 28)
    parts = []
    for i in range(count):
        up = X if i % 2 == 0 else normals[i]
        M = frame_matrix(pts[i], tangents[i], up)
        path2d = stadium
        path = np.column_stack([path2d, np.zeros(len(path2d))]) @ M[:3, :3].T + M[:3, 3]
        in_plane = _stadium_normals(path2d)
        n1 = np.column_stack([in_plane, np.zeros(len(in_plane))]) @ M[:3, :3].T
        n2 = np.tile(M[:3, 2], (len(path2d), 1))
        parts.append(sweep(path, n1, n2, circle2d(wire, 8)).with_uv(slot=slot))
    return parts, pts, tangents


def arc_length_frames(a: float, b: float, count: int, offset: float = 0.0, dense: int = 4096):
    """`count` points equally spaced by arc length on the curve running `offset` outside the ellipse (a, b)
    (its parallel curve), starting at t = 0; returns (points, unit tangents, outward unit normals), each (count, 3).
    """
    t = 2 * np.pi * np.arange(dense + 1) / dense
    nrm = np.stack([np.zeros_like(t), b * np.cos(t), a * np.sin(t)], 1)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    p = np.stack([np.zeros_like(t), a * np.cos(t), b * np.sin(t)], 1) + offset * nrm
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    ti = np.interp(np.arange(count) * s[-1] / count, s, t)
    n_i = np.stack([np.zeros(count), b * np.cos(ti), a * np.sin(ti)], 1)
    n_i /= np.linalg.norm(n_i, axis=1, keepdims=True)
    pts = np.stack([np.zeros(count), a * np.cos(ti), b * np.sin(ti)], 1) + offset * n_i
    tan = np.cross(X, n_i)                  # the curve runs counter-clockwise about +X
    return pts, tan, n_i


def offset_perimeter(a: float, b: float, offset: float) -> float:
    """Length of the curve running `offset` outside the ellipse (a, b): its perimeter + 2 pi offset."""
    return ellipse_perimeter(a, b) + 2 * np.pi * offset


def _stadium(L: float, H: float, m: int) -> np.ndarray:
    """(m, 2) counter-clockwise centreline of a stadium: long axis x (tips at +-L), straight sides at y = +-H."""
    straight, arc = 2 * (L - H), np.pi * H
    s = (np.arange(m) + 0.5) / m * 2 * (straight + arc)
    out = []
    for d in s:
        if d < straight:                               # bottom side, left to right
            out.append((-(L - H) + d, -H))
            continue
        d -= straight
        if d < arc:                                    # right end
            ang = -np.pi / 2 + d / H
            out.append(((L - H) + H * np.cos(ang), H * np.sin(ang)))
            continue
        d -= arc
        if d < straight:                               # top side, right to left
            out.append(((L - H) - d, H))
            continue
        d -= straight
        ang = np.pi / 2 + d / H                        # left end
        out.append((-(L - H) + H * np.cos(ang), H * np.sin(ang)))
    return np.array(out)


def _stadium_normals(p: np.ndarray) -> np.ndarray:
    t = np.roll(p, -1, 0) - np.roll(p, 1, 0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return np.stack([t[:, 1], -t[:, 0]], 1)


def gem(girdle_radius: float, facets: int = 16, slot: int = 3) -> list[Part]:
    """A round brilliant-like stone along +Z: girdle at z in [0, 0.04 d], crown to a table at 0.16 d,
    pavilion down to a culet at -0.43 d (d = diameter)."""
    d = 2 * girdle_radius
    fp = circle2d(girdle_radius, facets)
    return stacked_solid(fp, [0.0, 0.04 * d, 0.16 * d], [1.0, 1.0, 0.56], bottom_apex=-0.43 * d, side_slot=slot)


def cylinder_z(radius: float, z0: float, z1: float, m: int = 10, slot: int = 0) -> list[Part]:
    """A closed cylinder along +Z from z0 to z1."""
    return stacked_solid(circle2d(radius, m), [z0, z1], [1.0, 1.0], side_slot=slot)


def place(parts: list[Part], origin, x_axis, y_axis) -> list[Part]:
    """`stacked_solid` parts (footprint in x, y; height along z) moved to a frame given by its x and y axes."""
    return solid_parts(parts, frame_matrix(origin, x_axis, y_axis))


def rounded_box(hx: float, hy: float, z0: float, z1: float, power: float = 8.0, m: int = 32,
                slot: int = 0) -> list[Part]:
    """A box with rounded vertical edges (superellipse footprint hx x hy) from z0 to z1, edges bevelled."""
    bevel = min(0.15 * (z1 - z0), 0.2 * min(hx, hy))
    sx, sy = 1 - bevel / hx, 1 - bevel / hy
    fp = superellipse2d(hx, hy, m, power)
    heights = [z0, z0 + bevel, z1 - bevel, z1]
    # Non-uniform bevel scale: applied through the footprint so both axes lose the same length.
    levels = np.array([min(sx, sy), 1.0, 1.0, min(sx, sy)])
    return stacked_solid(fp, heights, levels, side_slot=slot)
