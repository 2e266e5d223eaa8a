"""A hand-shaped MANO-layout fixture built from tubes, with known UVs and labels by construction.

Palm: an elliptic tube along -X from the forearm end (x = +0.05, open) to the knuckles, capped. Fingers: round
tubes along -X (index at +Z, pinky at -Z), each with a rounded cap whose apex is the fingertip vertex. Thumb: a
tube toward +Z/-X whose back is rolled by `THUMB_ROLL` about its axis. Every joint is the centroid of a vertex
ring around its tube's axis, so J_regressor (ring averages) gives the joints exactly.

Each tube has its own UV island: angle around the axis -> u (with a duplicated seam column), arc length along
the axis -> v, at one texel density for all islands. Labels are assigned from the construction (angle from the
tube's back direction, axial position), independently of darthand's label derivation.
"""

from __future__ import annotations

import functools

import numpy as np
import scipy.sparse as sp

from darthand.model.hand_model import HandModel
from darthand.model.layout import FACE_LABEL_IDS, FINGER_JOINTS, FINGERS, MANO_PARENTS, NUM_POSE_FEATURES

SEG = 20  # vertices around each tube
THUMB_ROLL = 1.2
WRIST = np.zeros(3)
# name: (root, direction, length, radius); index nearest the thumb (+Z).
FINGER_SPECS = {
    "index": ((-0.080, 0.0, 0.026), (-1.0, 0.0, 0.05), 0.080, 0.0085),
    "middle": ((-0.082, 0.0, 0.008), (-1.0, 0.0, 0.0), 0.088, 0.0088),
    "ring": ((-0.080, 0.0, -0.010), (-1.0, 0.0, -0.04), 0.082, 0.0082),
    "pinky": ((-0.074, 0.0, -0.027), (-1.0, 0.0, -0.10), 0.065, 0.0072),
    "thumb": ((-0.018, -0.006, 0.032), (-0.55, -0.12, 0.82), 0.085, 0.0095),
}
JOINT_FRACTIONS = (0.0, 0.45, 0.74)  # root, middle and distal joints along each finger, as length fractions
NAIL_FROM = 0.84  # nail cap: beyond this fraction of the finger length, within NAIL_ANGLE of the back
NAIL_ANGLE = np.deg2rad(50)


def _frame(direction, roll=0.0):
    axis = np.asarray(direction, float) / np.linalg.norm(direction)
    up = np.array([0.0, 1.0, 0.0]) - axis[1] * axis
    up /= np.linalg.norm(up)
    side = np.cross(axis, up)
    side *= np.sign(side[2]) or 1.0
    back = np.cos(roll) * up + np.sin(roll) * side
    return axis, back, np.cross(axis, back)


def _tube(root, axis, back, lateral, stations, radii, cap_rings=4):
    """Rings at axial `stations` (metres from root) with radii (r_back, r_lateral) each, then a rounded cap to an
    apex (the last vertex).

    Returns vertices, outward faces, per-vertex (angle, s) with angle 0 at `back`, and each station's ring start.
    """
    angles = 2 * np.pi * np.arange(SEG) / SEG
    stations, radii = list(stations), list(radii)
    s_end, (rb_end, rl_end) = stations[-1], radii[-1]
    for k in range(1, cap_rings + 1):  # quarter-ellipse cap
        a = 0.5 * np.pi * k / (cap_rings + 1)
        stations.append(s_end + rb_end * np.sin(a))
        radii.append((rb_end * np.cos(a), rl_end * np.cos(a)))
    verts, params, ring_start = [], [], []
    for s, (rb, rl) in zip(stations, radii):
        ring_start.append(len(verts))
        for ang in angles:
            verts.append(root + s * axis + rb * np.cos(ang) * back + rl * np.sin(ang) * lateral)
            params.append((ang, s))
    apex = len(verts)
    verts.append(root + (s_end + rb_end) * axis)
    params.append((np.nan, s_end + rb_end))
    faces = []
    for r in range(len(stations) - 1):
        for k in range(SEG):
            a, b = r * SEG + k, r * SEG + (k + 1) % SEG
            faces += [(a, b, a + SEG), (b, b + SEG, a + SEG)]
    last = (len(stations) - 1) * SEG
    faces += [(last + k, last + (k + 1) % SEG, apex) for k in range(SEG)]
    verts, faces = np.array(verts), np.array(faces)
    tri = verts[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    rel = tri.mean(1) - root
    outward = rel - np.outer(rel @ axis, axis)
    if np.einsum("ij,ij->i", normal[:-SEG], outward[:-SEG]).sum() < 0:
        faces = faces[:, ::-1].copy()
    return verts, faces, np.array(params), ring_start


def hand_fixture(with_uvs: bool = True, with_labels: bool = True) -> HandModel:
    """The fixture as a HandModel (see the module docstring)."""
    verts, faces, params, labels, parts = [], [], [], [], []
    rings_of_joint, tips = {}, {}

    def add(part_verts, part_faces, part_params, part_labels, radius):
        off, foff = sum(len(v) for v in verts), sum(len(f) for f in faces)
        verts.append(part_verts), faces.append(part_faces + off), params.append(part_params)
        labels.append(part_labels)
        parts.append((off, len(part_verts), foff, len(part_faces), radius))
        return off

    # Palm tube: from x = +0.05 (open forearm end) to x = -0.085, elliptic, capped; ring at x = 0 is the wrist.
    axis, back, lateral = _frame((-1.0, 0.0, 0.0))
    root = np.array([0.05, 0.0, 0.0])
    stations = sorted(set(np.round(np.append(np.linspace(0.0, 0.13, 12), 0.05), 9)))
    radii = [(0.012 + 0.003 * np.clip((s - 0.04) / 0.04, 0, 1), 0.027 + 0.015 * np.clip((s - 0.03) / 0.05, 0, 1))
             for s in stations]
    v, f, p, ring_start = _tube(root, axis, back, lateral, stations, radii, cap_rings=3)
    cen = v[f].mean(1)
    lab = np.where((cen - root) @ back >= 0, FACE_LABEL_IDS["dorsum"], FACE_LABEL_IDS["palm"])
    lab = np.where(cen[:, 0] > WRIST[0], FACE_LABEL_IDS["wrist"], lab)
    off = add(v, f, p, lab, 0.022)
    rings_of_joint[0] = off + ring_start[stations.index(0.05)]

    for name in ("index", "middle", "ring", "pinky", "thumb"):
        froot, direction, length, radius = FINGER_SPECS[name]
        axis, back, lateral = _frame(direction, THUMB_ROLL if name == "thumb" else 0.0)
        froot = np.asarray(froot)
        tip_station = length - radius  # the rounded cap adds `radius`
        stations = sorted(set(np.round(np.concatenate([np.linspace(0, tip_station, 9),
                                                        np.array(JOINT_FRACTIONS) * length]), 9)))
        radii = [(radius * (1 - 0.12 * s / length), radius * (1.05 - 0.12 * s / length)) for s in stations]
        v, f, p, ring_start = _tube(froot, axis, back, lateral, stations, radii)
        rel = v[f].mean(1) - froot
        s = rel @ axis
        ang = np.arctan2(rel @ lateral, rel @ back)
        lab = np.where(np.cos(ang) >= 0, FACE_LABEL_IDS["finger_dorsal"], FACE_LABEL_IDS["finger_palmar"])
        nail = (s >= NAIL_FROM * length) & (np.abs(ang) <= NAIL_ANGLE) & (s <= length - 0.45 * radius)
        lab = np.where(nail, FACE_LABEL_IDS["nail"], lab)
        off = add(v, f, p, lab, radius)
        for j, frac in zip(FINGER_JOINTS[name], JOINT_FRACTIONS):
            rings_of_joint[j] = off + ring_start[stations.index(round(frac * length, 9))]
        tips[name] = off + len(v) - 1

    V, Fc = np.concatenate(verts), np.concatenate(faces)
    rows = np.repeat(np.arange(16), SEG)
    cols = np.concatenate([np.arange(rings_of_joint[j], rings_of_joint[j] + SEG) for j in range(16)])
    regressor = sp.csr_matrix((np.full(len(rows), 1.0 / SEG), (rows, cols)), shape=(16, len(V)))
    joints = regressor @ V
    weights = np.zeros((len(V), 16))
    weights[np.arange(len(V)), np.argmin(((V[:, None] - joints[None]) ** 2).sum(-1), 1)] = 1.0
    uvs = faces_uv = None
    if with_uvs:
        uvs, faces_uv = _island_uvs(parts, params, Fc)
    return HandModel.create(
        source="hand_fixture", v_template=V, faces=Fc, weights=weights,
        posedirs=np.zeros((len(V), 3, NUM_POSE_FEATURES)), J_regressor=regressor, parents=MANO_PARENTS,
        tip_ids=[tips[n] for n in FINGERS], uvs=uvs, faces_uv=faces_uv,
        face_labels=np.concatenate(labels) if with_labels else None, meta={"name": "hand_fixture"})


def _island_corners(face_params):
    """(fn, 3, 2) island coordinates (angle, s) of each face corner: angles unwrapped across the seam, the apex
    corner at the mean angle of the other two."""
    a = face_params[..., 0].copy()
    apex = np.isnan(a)
    b = np.where(apex, np.nanmin(a, axis=1, keepdims=True), a)
    wrap = (b.max(1) - b.min(1)) > np.pi  # the face crosses the seam at angle 0 = 2 pi: unwrap
    b[wrap] = np.where(b[wrap] < np.pi, b[wrap] + 2 * np.pi, b[wrap])
    others = np.where(apex, 0.0, b).sum(1) / (~apex).sum(1)
    b = np.where(apex, others[:, None], b)
    return np.stack([b, face_params[..., 1]], -1)


def _island_uvs(parts, params, faces):
    """One island per tube (u = angle * radius, v = axial, metres), placed on two shelves: palm and thumb, then
    the four fingers; one texel density everywhere; corners with equal UVs share a UV vertex."""
    islands = []
    for (off, _n, foff, fn, radius), p in zip(parts, params):
        c = _island_corners(p[faces[foff:foff + fn] - off])
        c[..., 0] *= radius
        islands.append(c - c.reshape(-1, 2).min(0))
    gap = 0.01
    shelves = [[0, 5], [1, 2, 3, 4]]  # parts: palm, index, middle, ring, pinky, thumb
    y, placed = gap, [None] * len(islands)
    width = 0.0
    for shelf in shelves:
        x = gap
        for i in shelf:
            placed[i] = islands[i] + [x, y]
            x += islands[i][..., 0].max() + gap
        width = max(width, x)
        y += max(islands[i][..., 1].max() for i in shelf) + gap
    extent = max(width, y)
    uvc = np.concatenate(placed).reshape(-1, 2) / extent
    key = np.round(uvc * 1e9).astype(np.int64)
    uniq, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return uvc[first], inverse.reshape(-1, 3)


# ----------------------------------------------------------------------------------------- shared helpers
@functools.lru_cache(maxsize=None)
def fixture_model(with_uvs: bool = True, with_labels: bool = True) -> HandModel:
    """`hand_fixture`, built once per test process."""
    return hand_fixture(with_uvs=with_uvs, with_labels=with_labels)


@functools.lru_cache(maxsize=None)
def fixture_bake(res: int = 128, atlas: bool = False):
    """The fixture's bake at `res` (its own UVs, or an xatlas atlas with `atlas=True`), once per process."""
    from darthand.model.atlas import ensure_uvs
    from darthand.textures.bake import bake

    model = ensure_uvs(fixture_model(with_uvs=False), res) if atlas else fixture_model()
    return bake(model, res)


@functools.lru_cache(maxsize=None)
def spec() -> dict:
    from darthand.textures.catalog import load_spec

    return load_spec()


@functools.lru_cache(maxsize=None)
def entries() -> tuple:
    from darthand.textures.catalog import expand_catalog

    return tuple(expand_catalog(spec()))


def entry(entry_id: str):
    return next(e for e in entries() if e.id == entry_id)
