"""Anatomical fields at surface points: how palmar, how close to a knuckle or fingertip, where inside a nail.

Each field is a smooth function of the rest-pose surface (position, interpolated normal), so it is continuous
across UV seams; skin bases and overlays scale and combine them. All lengths in metres.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from darthand.model.layout import FACE_LABEL_IDS, FINGER_JOINTS, FINGERS
from darthand.textures.noise import smoothstep
from darthand.model.regions import (Skeleton, face_geometry, hand_frame, nearest_bones, segment_coordinates,
                                       to_hand_frame)

# Dorsal knuckles: (joint index into FINGER_JOINTS chain, Gaussian radius in metres). Thumb: its 2nd and 3rd.
KNUCKLES = ((0, 0.0075), (1, 0.0055), (2, 0.0042))
TIP_RADIUS = 0.0075
_CHUNK = 1 << 18


def face_bones(vertices: np.ndarray, faces: np.ndarray, skel: Skeleton) -> np.ndarray:
    """Nearest bone of each face's centroid (F,) int64."""
    return nearest_bones(face_geometry(vertices, faces)[0], skel)[0]


def vertex_dorsal(vertices: np.ndarray, skel: Skeleton, softness: float = 0.004) -> np.ndarray:
    """(V, 3) unit 'back of the hand' direction per vertex: the bones' dorsal axes blended by a soft-min over
    distance (`softness` metres), so it turns smoothly from the palm (+Y) into the rolled thumb."""
    out = np.empty_like(vertices)
    for s in range(0, len(vertices), _CHUNK):
        dist, _ = segment_coordinates(vertices[s:s + _CHUNK], skel.start, skel.end)
        w = np.exp(-(dist - dist.min(1, keepdims=True)) / softness)
        d = w @ skel.dorsal
        out[s:s + _CHUNK] = d / np.linalg.norm(d, axis=1, keepdims=True)
    return out


def palmar_weight(normal: np.ndarray, dorsal: np.ndarray) -> np.ndarray:
    """(N,) in [0, 1]: 1 where the surface faces the palm side, 0 on the back, a short blend on the sides."""
    return smoothstep(-0.3, 0.3, -np.einsum("ij,ij->i", normal, dorsal))


def knuckle_points(vertices: np.ndarray, skel: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """Points on the back of the skin over each finger joint (K, 3) and their Gaussian radii (K,).

    For every finger and each of its three chain joints (the thumb's first, inside the palm, is skipped), the
    surface point is where the ray from the joint along the bone's dorsal axis leaves the skin: the ray point
    at the depth of the vertex closest to the ray.
    """
    points, radii = [], []
    for name in FINGERS:
        for level, radius in KNUCKLES:
            if name == "thumb" and level == 0:
                continue
            joint = skel.joints[FINGER_JOINTS[name][level]]
            up = skel.dorsal[skel.bone(name, level)]
            rel = vertices - joint
            along = rel @ up
            off_ray = np.linalg.norm(rel - np.outer(along, up), axis=1)
            ok = (along > 0) & (along < 0.04)
            best = np.argmin(np.where(ok, off_ray, np.inf))
            points.append(joint + along[best] * up)
            radii.append(radius)
    return np.array(points), np.array(radii)


def gaussian_max(points: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """max_k exp(-|p - c_k|^2 / (2 r_k^2)) at points (N, 3); (N,) float32."""
    out = np.zeros(len(points), np.float32)
    for c, r in zip(centres, radii):
        d2 = ((points - c.astype(np.float32)) ** 2).sum(1)
        np.maximum(out, np.exp(-d2 / np.float32(2 * r * r)), out=out)
    return out


def knuckle_wrinkles(points: np.ndarray, centres: np.ndarray, radii: np.ndarray, axes: np.ndarray,
                     spacing: float = 0.0011) -> np.ndarray:
    """Fine skin folds across the back of the knuckles: lines perpendicular to the finger axis, `spacing`
    metres apart, under an elliptic envelope around each knuckle point; (N,) float32 in [0, 1]."""
    out = np.zeros(len(points), np.float32)
    for c, r, axis in zip(centres, radii, axes):
        rel = points - c.astype(np.float32)
        a = rel @ axis.astype(np.float32)
        lateral2 = (rel ** 2).sum(1) - a * a
        env = np.exp(-(a * a) / np.float32(2 * (0.9 * r) ** 2) - lateral2 / np.float32(2 * (0.75 * r) ** 2))
        lines = (0.5 + 0.5 * np.cos(a * np.float32(2 * np.pi / spacing))) ** 6
        np.maximum(out, env * lines, out=out)
    return out


def nail_plates(points: np.ndarray, normals: np.ndarray, bone: np.ndarray, labelled_nail: np.ndarray,
                skel: Skeleton, texel_size: float):
    """Smooth nail plates, one per finger, fitted to that finger's nail-labelled points.

    Face labels outline a nail only to the mesh's resolution (a zigzag on MANO); the plate is a rounded
    rectangle in nail coordinates instead: u along the distal bone from the nail fold (0) to the free edge (1),
    v across (-1 .. 1), extents from robust percentiles of the labelled points, a fold curved toward the
    corners. Only points of the distal segment's back are candidates.

    Returns coverage (N,) in [0, 1] (anti-aliased over one texel), nail_u, nail_v (N,) float32 (0 where not a
    candidate).
    """
    cover = np.zeros(len(points), np.float32)
    nail_u = np.zeros(len(points), np.float32)
    nail_v = np.zeros(len(points), np.float32)
    for name in FINGERS:
        b = skel.bone(name, 2)
        on_bone = bone == b
        fit = on_bone & labelled_nail
        if fit.sum() < 3:
            continue
        axis, up = skel.axis(b), skel.dorsal[b]
        side = np.cross(axis, up)
        rel = points - skel.start[b]
        a, lat = rel @ axis, rel @ side
        a_lo, a_hi = np.percentile(a[fit], 1.0), np.percentile(a[fit], 99.5)
        centre = float(np.median(lat[fit]))
        half = max(float(np.percentile(np.abs(lat[fit] - centre), 97.0)), 1e-4)
        length = max(a_hi - a_lo, 1e-4)
        cand = on_bone & (rel @ up > 0) & (normals @ up > 0.15)
        u = (a[cand] - a_lo) / length
        v = (lat[cand] - centre) / half
        fold = 0.04 + 0.3 * v ** 4  # the proximal fold curves forward into rounded corners
        dist = np.maximum.reduce([(np.abs(v) - 1.0) * half, (fold - u) * length, (u - 1.0) * length])
        cover[cand] = 1.0 - smoothstep(-0.5 * texel_size, 0.5 * texel_size, dist)
        nail_u[cand] = np.clip(u, -0.5, 1.5)
        nail_v[cand] = np.clip(v, -1.5, 1.5)
    return cover, nail_u, nail_v


def distance_to(points: np.ndarray, targets: np.ndarray, limit: float) -> np.ndarray:
    """Distance (N,) from each point to the nearest target point, capped at `limit` metres."""
    if len(targets) == 0:
        return np.full(len(points), limit, np.float32)
    d, _ = cKDTree(targets).query(points, distance_upper_bound=limit)
    return np.minimum(d, limit).astype(np.float32)


VEIN_PATTERNS = 3
VEIN_SEED = 0x7E1


def vein_curves(skel: Skeleton, rng: np.random.Generator) -> list[tuple[np.ndarray, float, bool]]:
    """One plausible layout of superficial veins as curves in hand-frame coordinates (f, s) (see
    regions.hand_frame): (control points (K, 2), width in metres, on the palm side?).

    The back of the hand: veins rising from the finger webs, joining an arch across the back of the hand,
    draining into the cephalic (thumb side) and basilic (little-finger side) veins up the forearm. The inner
    wrist: a few wavy lengthwise veins. Every path meanders through jittered intermediate points.
    """
    frame = hand_frame(skel)
    roots = {n: to_hand_frame(skel.joints[FINGER_JOINTS[n][0]][None, [0, 2]], frame)[0] for n in FINGERS}
    arch_f = rng.uniform(0.38, 0.55)
    bow = rng.uniform(0.05, 0.15)

    def width(lo, hi):
        return float(rng.uniform(lo, hi)) * 1e-3

    def meander(points, wiggle=0.018, steps=2):
        """Insert `steps` jittered points between consecutive points (f, s)."""
        pts = [np.asarray(points[0], float)]
        for a, b in zip(points[:-1], points[1:]):
            a, b = np.asarray(a, float), np.asarray(b, float)
            for t in np.linspace(0, 1, steps + 2)[1:-1]:
                pts.append(a + t * (b - a) + rng.normal(0.0, wiggle, 2))
            pts.append(b)
        return np.array(pts)

    curves = []
    webs = [("index", "middle"), ("middle", "ring"), ("ring", "pinky"), ("thumb", "index")]
    for a, b in webs:
        if rng.random() < 0.25:
            continue
        s_web = 0.5 * (roots[a][1] + roots[b][1]) if a != "thumb" else 0.85
        f_web = 0.98 if a != "thumb" else 0.75
        s_end = s_web * rng.uniform(0.5, 0.9)
        curves.append((meander([(f_web, s_web), (0.72, s_web), (arch_f + bow * (1 - s_end ** 2), s_end)]),
                       width(1.8, 2.6), False))
    arch = meander([(arch_f - 0.05, -1.05), (arch_f + bow, -0.35), (arch_f + bow, 0.35), (arch_f - 0.05, 0.95)],
                   0.015, 2)
    curves.append((arch, width(2.0, 2.8), False))
    curves.append((meander([(arch_f - 0.05, 0.95), (0.1, 0.95), (-0.35, 0.75), (-0.8, 0.55)]), width(2.6, 3.4), False))
    curves.append((meander([(arch_f - 0.05, -1.05), (0.1, -0.9), (-0.35, -0.6), (-0.8, -0.35)]), width(2.4, 3.2),
                   False))
    for s0 in rng.uniform(-0.5, 0.5, int(rng.integers(2, 4))):
        curves.append((meander([(0.12, s0), (-0.3, s0 + rng.normal(0, 0.1)), (-0.8, s0 + rng.normal(0, 0.15))]),
                       width(1.6, 2.4), True))
    return curves


def _spline(points: np.ndarray, per_segment: int = 24) -> np.ndarray:
    """A smooth curve through `points` (K, 2): Catmull-Rom, `per_segment` samples between neighbours."""
    p = np.concatenate([points[:1], points, points[-1:]])
    t = np.linspace(0.0, 1.0, per_segment, endpoint=False)[:, None]
    out = []
    for i in range(1, len(p) - 2):
        p0, p1, p2, p3 = p[i - 1], p[i], p[i + 1], p[i + 2]
        out.append(0.5 * (2 * p1 + (p2 - p0) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t ** 2
                          + (3 * p1 - p0 - 3 * p2 + p3) * t ** 3))
    out.append(p[-2:-1])
    return np.concatenate(out)


def vein_patterns(position: np.ndarray, palmar: np.ndarray, bone: np.ndarray, skel: Skeleton,
                  count: int = VEIN_PATTERNS) -> dict[str, np.ndarray]:
    """`count` alternative vein layouts (fixed seeds) as fields 'veins<k>' (N,) float32 in [0, 1]: a soft
    profile across each vein, distance measured in the palm's plane, on the hand and forearm only."""
    frame = hand_frame(skel)
    origin, f_vec, s_vec = frame
    on_hand = np.isin(bone, [skel.palm_bone(n) for n in FINGERS] + [skel.forearm_bone])
    out = {}
    for k in range(count):
        rng = np.random.default_rng([VEIN_SEED, k])
        field = np.zeros(len(position), np.float32)
        for palm_side in (False, True):
            sel = np.nonzero(on_hand & ((palmar > 0.5) == palm_side))[0]
            pieces = [(_spline(c), wd) for c, wd, side in vein_curves(skel, rng if not palm_side else
                                                                          np.random.default_rng([VEIN_SEED, k, 1]))
                      if side == palm_side]
            if not pieces or not len(sel):
                continue
            pts = np.concatenate([origin + np.outer(c[:, 0], f_vec) + np.outer(c[:, 1], s_vec) for c, _ in pieces])
            widths = np.concatenate([np.full(len(c), wd) for c, wd in pieces])
            d, i = cKDTree(pts).query(position[sel][:, [0, 2]], distance_upper_bound=3 * widths.max())
            hit = np.isfinite(d)
            prof = np.zeros(len(sel), np.float32)
            prof[hit] = np.exp(-(d[hit] / widths[i[hit]]) ** 2)
            field[sel] = prof
        out[f"veins{k}"] = field
    return out


def texel_labels(face_label: np.ndarray, nail: np.ndarray, bone: np.ndarray, skel: Skeleton) -> np.ndarray:
    """Per-texel labels (N,) int8: the face's label, except on distal segments where the smooth nail plate
    decides nail (coverage >= 0.5) versus finger_dorsal."""
    labels = face_label.astype(np.int8).copy()
    distal = np.isin(bone, [skel.bone(n, 2) for n in FINGERS])
    labels[distal & (nail >= 0.5)] = FACE_LABEL_IDS["nail"]
    labels[distal & (nail < 0.5) & (labels == FACE_LABEL_IDS["nail"])] = FACE_LABEL_IDS["finger_dorsal"]
    return labels


def anatomy_fields(position: np.ndarray, normal: np.ndarray, face: np.ndarray, bary: np.ndarray,
                   vertices: np.ndarray, faces: np.ndarray, face_labels: np.ndarray,
                   skel: Skeleton, texel_size: float) -> dict[str, np.ndarray]:
    """Every anatomical field at N surface points given by their face (N,) and barycentrics (N, 3).

    Returns float32 (N,) fields unless noted:
        bone       int8, nearest bone of the point's face (Skeleton order)
        finger     int8, FINGERS index of that bone, -1 for the forearm
        palmar     1 on the palm side, 0 on the back
        wrist      0 on the hand, 1 on the forearm (beyond the wrist joint along +X)
        knuckle    Gaussian bumps over the back of every finger joint
        wrinkle    knuckle skin folds (lines) in [0, 1]
        tip        Gaussian around each fingertip
        nail       smooth nail-plate coverage in [0, 1] (see `nail_plates`)
        nail_u, nail_v   coordinates in and around the nail plates
        cuticle    1 at a nail's edge falling to 0 two millimetres away (0 on the nail itself)
        veins<k>   alternative layouts of superficial veins (see `vein_patterns`)
    """
    fbone = face_bones(vertices, faces, skel)
    bone = fbone[face]
    finger = skel.finger[bone]
    dorsal_v = vertex_dorsal(vertices, skel)
    dorsal = np.einsum("nk,nki->ni", bary, dorsal_v[faces[face]])
    dorsal /= np.linalg.norm(dorsal, axis=1, keepdims=True)
    pos32 = position.astype(np.float32)
    kpts, kradii = knuckle_points(vertices, skel)
    kaxes = np.array([skel.axis(skel.bone(n, lvl)) for n in FINGERS for lvl, _ in KNUCKLES
                      if not (n == "thumb" and lvl == 0)])
    nail, nail_u, nail_v = nail_plates(position, normal, bone, face_labels[face] == FACE_LABEL_IDS["nail"], skel,
                                       texel_size)
    is_nail = nail >= 0.5
    cuticle = np.zeros(len(position), np.float32)
    distal = np.isin(bone, [skel.bone(n, 2) for n in FINGERS]) & ~is_nail
    cuticle[distal] = 1.0 - distance_to(position[distal], position[is_nail], 0.002) / 0.002
    palmar = palmar_weight(normal, dorsal).astype(np.float32)
    return {
        **vein_patterns(position, palmar, bone, skel),
        "bone": bone.astype(np.int8),
        "finger": finger.astype(np.int8),
        "palmar": palmar,
        "wrist": smoothstep(skel.joints[0, 0] - 0.015, skel.joints[0, 0] + 0.035, position[:, 0]),
        "knuckle": gaussian_max(pos32, kpts, kradii),
        "wrinkle": knuckle_wrinkles(pos32, kpts, kradii, kaxes),
        "tip": gaussian_max(pos32, skel.tips, np.full(5, TIP_RADIUS)),
        "nail": nail,
        "nail_u": nail_u,
        "nail_v": nail_v,
        "cuticle": cuticle,
    }
