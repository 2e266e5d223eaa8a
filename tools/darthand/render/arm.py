"""An arm that goes on: render-time forearm geometry continuing the hand's forearm cut out of the frame, in place of
the flat cap (model/cap.py) that closes it in the packages.

The forearm is a tube of rings over the model's forearm loop (the cut the cap closes), extruded along the loop
plane's normal (model/wrist.loop_frame): ring 0 copies the loop (each vertex carries its hand vertex's rest position,
skin weights, pose correctives and shape directions, so the seam stays closed in every pose and shape, as the cap's
rim does); the rings beyond blend to the root joint alone over BLEND_M (the forearm moves rigidly with the wrist
joint, not with the palm's finger-driven deformation) and to no correctives. Like a real forearm it widens from
the wrist (WIDEN of the wrist's radius over WIDEN_M) and its flattened wrist section rounds out (ROUND). A small
cap closes the far end, `length` metres from the cut. UVs: each ring repeats the loop's UVs around (the model's
wrist band, per edge so a UV seam on the loop stays a seam), and along the arm the band's V is walked back and
forth (mirrored at its ends) at the band's own texel density, so the wrist's skin texture continues undistorted.

The hand mesh, its vertex numbering and every label stay the model's: the arm is a surface of the frame only.

Shapes: L loop vertices, R rings after the loop; the arm's vertices are (R + 1) L ring vertices then the far centre.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darthand.errors import InputError
from darthand.model.cap import ForearmCap, forearm_cap
from darthand.model.hand_model import HandModel
from darthand.model.wrist import loop_frame, ring_faces

RINGS = 12            # rings after the loop: enough for the widening profile to read as a curve
BLEND_M = 0.03        # over this distance from the cut the rings' skinning blends from the loop's to the root's
WIDEN = 0.3           # the forearm's radius grows by this share of the wrist's ...
WIDEN_M = 0.15        # ... over this distance from the cut (a forearm is widest below the elbow)
ROUND = 0.5           # share of the flattened wrist section rounded to a circle at WIDEN_M
MIN_LENGTH, MAX_LENGTH = 0.02, 2.0
ARM_ON_M = 0.3        # `--arm on`: a forearm's length past the wrist, about to the elbow
ARM, ARM_END = "forearm", "forearm_end"     # the surfaces' names: the tube (role 'arm'), its far end (role 'cap')


@dataclass(frozen=True)
class Arm:
    """A model's arm: `skin` its rig in the cap's form (vertices (C, 3), faces, weights, posedirs, shapedirs, uvs,
    faces_uv; posed by ForearmCap.pose), its first `tube_faces` faces the tube over the first `tube_vertices`
    vertices, the rest the far end's fan; `ring_size` L; `length` metres."""

    skin: ForearmCap
    tube_faces: int
    tube_vertices: int
    ring_size: int
    length: float


def check_length(length) -> float:
    """The arm's length in metres (InputError outside MIN_LENGTH..MAX_LENGTH)."""
    if not (isinstance(length, (int, float, np.number)) and MIN_LENGTH <= float(length) <= MAX_LENGTH):
        raise InputError(f"arm: {length!r} is not a length in metres in [{MIN_LENGTH}, {MAX_LENGTH}] (0: off)")
    return float(length)


def ring_distances(length: float, rings: int = RINGS) -> np.ndarray:
    """(rings + 1,) distances of the rings from the cut (metres), 0 first: denser near the wrist, where the profile
    bends and the camera usually is."""
    t = np.linspace(0.0, 1.0, rings + 1)
    return length * t ** 1.5


def widening(d: np.ndarray) -> np.ndarray:
    """(R,) radius scale of rings at distances d (metres): 1 at the cut, 1 + WIDEN from WIDEN_M on, smoothstep
    between."""
    s = np.clip(d / WIDEN_M, 0.0, 1.0)
    return 1.0 + WIDEN * s * s * (3 - 2 * s)


def forearm_arm(model: HandModel, length: float) -> Arm:
    """The arm of `model` reaching `length` metres (check_length) past its forearm cut."""
    length = check_length(length)
    cap = forearm_cap(model)
    loop = cap.loop
    L = len(loop)
    pts = model.v_template[loop]
    centre, axis, radius = loop_frame(model, loop)
    d = ring_distances(length)
    rel = pts - centre
    along = rel @ axis
    planar = rel - np.outer(along, axis)
    circle = planar / np.maximum(np.linalg.norm(planar, axis=1, keepdims=True), 1e-12) * radius
    grow, rounded = widening(d), ROUND * np.clip(d / WIDEN_M, 0.0, 1.0)
    rings = [pts] + [centre + axis * dk + gk * ((1 - rk) * planar + rk * circle)
                     for dk, gk, rk in zip(d[1:], grow[1:], rounded[1:])]
    far_centre = centre + axis * d[-1]
    vertices = np.concatenate(rings + [far_centre[None]])
    blend = np.clip(d / BLEND_M, 0.0, 1.0)[:, None, None]                          # (R + 1, 1, 1)
    root = np.zeros((1, 1, model.weights.shape[1]))
    root[..., 0] = 1.0
    weights = ((1 - blend) * model.weights[loop][None] + blend * root).reshape(-1, model.weights.shape[1])
    weights = np.concatenate([weights, root[0]])
    posedirs = ((1 - blend[..., None]) * model.posedirs[loop][None]).reshape(-1, *model.posedirs.shape[1:])
    posedirs = np.concatenate([posedirs, np.zeros((1,) + model.posedirs.shape[1:])])
    shapedirs = _ring_shapedirs(model.shapedirs[loop], grow)
    ring_ids = np.arange((len(d)) * L).reshape(len(d), L)
    tube = ring_faces(ring_ids)
    far = len(vertices) - 1
    last = ring_ids[-1]
    end = np.stack([np.roll(last, -1), last, np.full(L, far)], axis=1)     # as the cap: facing out of the arm
    faces = np.concatenate([tube, end])
    uvs = faces_uv = None
    if cap.uvs is not None:
        uvs, faces_uv = _arm_uvs(model, cap, d)
    skin = ForearmCap(vertices, faces, weights, posedirs, shapedirs, uvs, faces_uv, loop)
    return Arm(skin, len(tube), len(d) * L, L, length)


def _ring_shapedirs(loop_dirs: np.ndarray, grow: np.ndarray) -> np.ndarray:
    """((R + 1) L + 1, 3, S) shape directions: each ring's loop directions about their mean, scaled as the ring
    (a wider wrist widens the arm), the far centre the mean's."""
    mean = loop_dirs.mean(axis=0, keepdims=True)
    rings = [mean + g * (loop_dirs - mean) for g in grow]
    return np.concatenate(rings + [mean])


def _arm_uvs(model: HandModel, cap: ForearmCap, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(uvs (2 (R + 1) L + 1, 2), faces_uv) of the arm: per ring and loop edge the edge's two rim UVs (the cap's),
    V walked along the wrist band (`band_walk`); the far centre the mean of the last ring's."""
    assert cap.uvs is not None
    L = len(cap.loop)
    rim = cap.uvs[:2 * L].reshape(L, 2, 2)                          # edge i: UVs of its start and end
    v_rim = float(rim[..., 1].mean())
    v_of = band_walk(model, v_rim, d)                               # (R + 1,)
    grid = np.repeat(rim[None], len(d), axis=0).copy()              # (R + 1, L, 2, 2)
    grid[..., 1] = v_of[:, None, None]
    uvs = np.concatenate([grid.reshape(-1, 2), grid[-1].reshape(-1, 2).mean(0, keepdims=True)])
    idx = np.arange(len(d) * L * 2).reshape(len(d), L, 2)
    a, b = idx[:-1, :, 0], idx[:-1, :, 1]             # ring r, edge i: start (loop i) and end (loop i + 1)
    c, e = idx[1:, :, 0], idx[1:, :, 1]
    tube = np.stack([np.stack([b, a, c], -1), np.stack([b, c, e], -1)], axis=2).reshape(-1, 3)
    far = len(uvs) - 1
    end = np.stack([idx[-1, :, 1], idx[-1, :, 0], np.full(L, far)], axis=1)
    return uvs, np.concatenate([tube, end])


def band_walk(model: HandModel, v_rim: float, d: np.ndarray) -> np.ndarray:
    """(R + 1,) V of rings at distances d (metres) from the cut: back into the wrist band (the UVs of the model's
    wrist-ring faces, model/wrist.py) at its texel density (band height / ring length), mirrored at the band's
    ends; v_rim everywhere when the model has no wrist band."""
    wrist = model.meta.get("wrist") or {}
    if model.faces_uv is None or model.uvs is None or not wrist.get("base_faces") or not wrist.get("length_m"):
        return np.full(len(d), v_rim)
    band_v = model.uvs[model.faces_uv[int(wrist["base_faces"]):].reshape(-1), 1]
    far_v = band_v.min() if abs(band_v.min() - v_rim) > abs(band_v.max() - v_rim) else band_v.max()
    height = far_v - v_rim                                              # signed: toward the band's other end
    phase = np.mod(d / float(wrist["length_m"]), 2.0)
    return v_rim + height * np.where(phase <= 1.0, phase, 2.0 - phase)


def shorten_before(vertices: np.ndarray, origin: np.ndarray, axis: np.ndarray, camera_centre: np.ndarray,
                   radius: float, reach: float, rim: np.ndarray) -> np.ndarray:
    """Posed arm vertices (V, 3), ring by ring over the loop's L vertices (a trailing vertex after the last whole
    ring, the far centre, keeps its offset from the axis), cut back to a prism of the cut's own section `rim` (L, 3)
    reaching MIN_LENGTH along `axis` (unit) from `origin` (the cut's centre) when the camera looks along the arm
    from inside its half-cylinder (within `radius` of the axis, ahead of the cut): from there any arm would hide the
    hand behind its far end, so the frame shows the cut much as it would without the option. The same array when
    the camera is clear of it (or the arm is no longer than MIN_LENGTH)."""
    rel = np.asarray(camera_centre, np.float64) - origin
    ahead = float(rel @ axis)
    off_axis = float(np.linalg.norm(rel - ahead * axis))
    if ahead <= 0 or off_axis > radius or reach <= MIN_LENGTH:
        return vertices
    v = np.asarray(vertices, np.float64)
    along = np.maximum((v - origin) @ axis, 0.0)
    out = v - np.outer(along, axis)                                    # onto the cut's plane ...
    L = len(rim)
    whole = len(v) // L * L
    rim_plane = rim - np.outer((rim - origin) @ axis, axis)
    out[:whole] = np.tile(rim_plane, (len(v) // L, 1))                 # ... in the cut's own section
    out += np.outer(along * (MIN_LENGTH / reach), axis)
    return out.astype(vertices.dtype)
