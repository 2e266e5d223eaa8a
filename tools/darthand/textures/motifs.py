"""Vector tattoo motifs as 2D signed distance functions (negative inside), about [-1, 1]^2 in size.

Each motif maps points (M, 2) to distances (M,); composing them with min/max keeps edges exact, so the ink edge
can be anti-aliased at any texture resolution. `band` motifs are made for the cylindrical coordinates around a
finger or the wrist (x along the axis, y around it, periodic).
"""

from __future__ import annotations

import numpy as np


def circle(p, c, r):
    return np.hypot(p[:, 0] - c[0], p[:, 1] - c[1]) - r


def ring(p, c, r, w):
    return np.abs(circle(p, c, r)) - w


def segment(p, a, b, w):
    """Capsule of half-width w around segment a-b."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    pa, ba = p - a, b - a
    h = np.clip((pa @ ba) / (ba @ ba), 0.0, 1.0)
    return np.linalg.norm(pa - h[:, None] * ba, axis=1) - w


def box(p, c, half):
    d = np.abs(p - np.asarray(c, float)) - np.asarray(half, float)
    return np.linalg.norm(np.maximum(d, 0.0), axis=1) + np.minimum(d.max(1), 0.0)


def polygon(p, verts):
    """Signed distance to a simple polygon (K, 2) (even-odd inside test)."""
    v = np.asarray(verts, float)
    d = np.full(len(p), np.inf)
    inside = np.zeros(len(p), bool)
    for i in range(len(v)):
        a, b = v[i], v[i - 1]
        e, w = b - a, p - a
        h = np.clip((w @ e) / (e @ e), 0.0, 1.0)
        d = np.minimum(d, np.linalg.norm(w - h[:, None] * e, axis=1))
        crosses = (p[:, 1] >= a[1]) != (p[:, 1] >= b[1])
        x_at = a[0] + (p[:, 1] - a[1]) * e[0] / np.where(e[1] == 0, 1e-12, e[1])
        inside ^= crosses & (p[:, 0] < x_at)
    return np.where(inside, -d, d)


def ellipse(p, c, r):
    """Approximate signed distance to an axis-aligned ellipse (exact on the axes)."""
    q = (p - np.asarray(c, float)) / np.asarray(r, float)
    k = np.linalg.norm(q, axis=1)
    return (k - 1.0) * min(r)


def star_points(n, r_out, r_in, rot=np.pi / 2):
    a = rot + np.pi * np.arange(2 * n) / n
    r = np.where(np.arange(2 * n) % 2 == 0, r_out, r_in)
    return np.stack([r * np.cos(a), r * np.sin(a)], 1)


def rotate(p, angle):
    c, s = np.cos(angle), np.sin(angle)
    return p @ np.array([[c, -s], [s, c]])


def union(*d):
    return np.minimum.reduce(d)


# ---------------------------------------------------------------------------------------------- motifs
def star(p):
    return polygon(p, star_points(5, 0.95, 0.4))


def heart(p):
    # Inigo Quilez's exact heart, mapped to [-1, 1].
    q = p / 1.05 + [0.0, 0.55]
    q = np.stack([np.abs(q[:, 0]), q[:, 1]], 1)
    upper = np.hypot(q[:, 0] - 0.25, q[:, 1] - 0.75) - np.sqrt(2) / 4
    m = 0.5 * np.maximum(q[:, 0] + q[:, 1], 0)
    lower = np.sqrt(np.minimum(q[:, 0] ** 2 + (q[:, 1] - 1) ** 2, (q[:, 0] - m) ** 2 + (q[:, 1] - m) ** 2))
    lower *= np.sign(q[:, 0] - q[:, 1])
    return np.where(q[:, 1] + q[:, 0] > 1, upper, lower) * 1.05


def anchor(p):
    w = 0.075
    arc = np.maximum(ring(p, (0, 0.05), 0.68, w), p[:, 1] + 0.2)
    flukes = union(polygon(p, [(-0.78, -0.05), (-0.55, -0.2), (-0.72, -0.35)]),
                   polygon(p, [(0.78, -0.05), (0.55, -0.2), (0.72, -0.35)]))
    return union(ring(p, (0, 0.78), 0.15, w), segment(p, (0, 0.62), (0, -0.66), w),
                 segment(p, (-0.38, 0.38), (0.38, 0.38), w), arc, flukes)


def moon(p):
    return np.maximum(circle(p, (0, 0), 0.9), -circle(p, (0.38, 0.18), 0.75))


def sun(p):
    rays = [segment(p, 0.52 * np.array([np.cos(a), np.sin(a)]), (0.92 if i % 2 == 0 else 0.75) *
                    np.array([np.cos(a), np.sin(a)]), 0.06)
            for i, a in enumerate(np.linspace(0, 2 * np.pi, 12, endpoint=False))]
    return union(circle(p, (0, 0), 0.38), *rays)


def arrow(p):
    w = 0.05
    return union(segment(p, (-0.9, 0), (0.7, 0), w), polygon(p, [(0.98, 0), (0.6, 0.2), (0.6, -0.2)]),
                 segment(p, (-0.9, 0), (-1.05, 0.18), w), segment(p, (-0.9, 0), (-1.05, -0.18), w),
                 segment(p, (-0.75, 0), (-0.9, 0.18), w), segment(p, (-0.75, 0), (-0.9, -0.18), w))


def mandala(p):
    w = 0.04
    petals = []
    for a in np.linspace(0, 2 * np.pi, 8, endpoint=False):
        q = rotate(p, -a)
        petals.append(np.abs(ellipse(q, (0.62, 0), (0.28, 0.14))) - w)
    return union(ring(p, (0, 0), 0.2, w), ring(p, (0, 0), 0.36, w), ring(p, (0, 0), 0.95, w), circle(p, (0, 0), 0.08),
                 *petals)


def triangles(p):
    w = 0.045
    outs = []
    for s in (1.0, 0.68, 0.36):
        tri = s * np.array([(0, 0.95), (-0.85, -0.55), (0.85, -0.55)])
        outs.append(np.abs(polygon(p, tri)) - w)
    return union(*outs)


def infinity(p):
    return union(ring(p, (-0.45, 0), 0.4, 0.06), ring(p, (0.45, 0), 0.4, 0.06))


def waves(p):
    outs = []
    for off in (-0.45, 0.0, 0.45):
        f = off + 0.2 * np.sin(3.2 * p[:, 0])
        slope = 0.64 * np.cos(3.2 * p[:, 0])
        d = np.abs(p[:, 1] - f) / np.sqrt(1 + slope ** 2) - 0.055
        outs.append(np.maximum(d, np.abs(p[:, 0]) - 0.95))
    return union(*outs)


def snowflake(p):
    w = 0.05
    parts = []
    for a in np.linspace(0, 2 * np.pi, 6, endpoint=False):
        q = rotate(p, -a)
        parts += [segment(q, (0, 0), (0.95, 0), w), segment(q, (0.55, 0), (0.75, 0.18), w),
                  segment(q, (0.55, 0), (0.75, -0.18), w)]
    return union(*parts)


def cross(p):
    return union(box(p, (0, -0.1), (0.13, 0.85)), box(p, (0, 0.35), (0.5, 0.12)))


def diamond(p):
    outer = np.array([(0, 0.95), (0.6, 0), (0, -0.95), (-0.6, 0)])
    return union(np.abs(polygon(p, outer)) - 0.05, polygon(p, 0.4 * outer))


def paw(p):
    return union(ellipse(p, (0, -0.3), (0.42, 0.36)), ellipse(p, (-0.55, 0.2), (0.16, 0.22)),
                 ellipse(p, (-0.2, 0.55), (0.16, 0.22)), ellipse(p, (0.2, 0.55), (0.16, 0.22)),
                 ellipse(p, (0.55, 0.2), (0.16, 0.22)))


def semicolon(p):
    tail = np.maximum(np.maximum(ring(p, (-0.3, -0.2), 0.28, 0.08), -(p[:, 0] + 0.3)), p[:, 1] + 0.2)
    return union(circle(p, (0, 0.5), 0.2), circle(p, (0, -0.2), 0.2), tail)


def compass(p):
    return union(ring(p, (0, 0), 0.9, 0.04), polygon(p, star_points(4, 0.8, 0.18)),
                 polygon(p, rotate(star_points(4, 0.45, 0.12), np.pi / 4)))


def lightning(p):
    return polygon(p, [(0.15, 0.95), (-0.45, 0.0), (-0.02, 0.0), (-0.2, -0.95), (0.45, 0.15), (0.05, 0.15)])


def note(p):
    return union(ellipse(rotate(p - [-0.25, -0.6], 0.4) + [-0.25, -0.6], (-0.25, -0.6), (0.3, 0.2)),
                 segment(p, (0.02, -0.55), (0.02, 0.9), 0.05),
                 segment(p, (0.02, 0.9), (0.45, 0.55), 0.06))


def dots(p):
    return union(*(circle(p, (x, 0), 0.16) for x in (-0.7, -0.23, 0.23, 0.7)))


BAND_PERIOD = 0.5  # period of band patterns around the axis, motif units


def band(p, period: float = BAND_PERIOD):
    """Two lines around a finger or wrist with a zigzag between; p = (axial, around) in motif units."""
    zig = np.abs(((p[:, 1] / period) % 1.0) - 0.5) * 2.0 - 0.5  # triangle wave in [-0.5, 0.5]
    return union(np.abs(p[:, 0] - 0.7) - 0.07, np.abs(p[:, 0] + 0.7) - 0.07, np.abs(p[:, 0] - 0.9 * zig) - 0.07)


def ring_line(p):
    """A single thin ring around a finger (a 'wedding band' tattoo)."""
    return np.abs(p[:, 0]) - 0.25


MOTIFS = {
    "star": star, "heart": heart, "anchor": anchor, "moon": moon, "sun": sun, "arrow": arrow, "mandala": mandala,
    "triangles": triangles, "infinity": infinity, "waves": waves, "snowflake": snowflake, "cross": cross,
    "diamond": diamond, "paw": paw, "semicolon": semicolon, "compass": compass, "lightning": lightning,
    "note": note, "dots": dots,
}
BAND_MOTIFS = {"band": band, "ring_line": ring_line}
