"""Pose sampling for datasets: reference sets, DART's grid-and-slerp sampler, gestures with jitter.

Poses are sampled for a right hand (the model's right-handed twin) as MANO axis-angle relative to the flat hand,
finger joints only (the root is zero: the view gives the hand's orientation); a left-hand frame takes the mirror
image of its pose (model.mirror.mirror_pose), so both hands see the same distribution.

DART's sampler (`GridSlerp`), after the DART paper: frames come in groups of `steps` (default 8). A group draws a
base pose from a grid of anatomical angles (model/anatomy.py's twist/spread/bend space, within the joint limits):
each digit's legal axes are discretised into `levels` values and each digit draws its own cell, so the grid's cells
are permuted across the fingers. Then `draws` poses (DART: 2,000) are drawn from a reference set and the one that
differs most from the base (largest sum over the 15 finger joints of the rotation angle between the two) is kept;
the group's frames walk from the base (t = 0) to that reference pose (t = 1) along per-joint quaternion slerps.

Reference sets (`ReferenceSet`): the gesture library (default), the pose library ('library', or a tagged subset
'library:alphabet'), a darthand pose file (schemas/pose.schema.json),
or FreiHAND's `training_mano.json` read directly (rows of 61 numbers: 48 pose values with MANO's mean hand not
included, i.e. flat_hand_mean false, 10 betas, 2 root position in the image, 1 scale; only the 45 finger values are
used). Files are read within a budget (`max_bytes`), since a JSON number costs ~30 bytes of memory once parsed.

Randomness: group g draws from numpy's Generator seeded with [seed, POSE_STREAM, g]; a frame's pose depends only on
(seed, its index) and the options.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import read_json
from darthand.model.anatomy import angles_to_axis_angle, axis_angle_to_angles, joint_frames, limits_radians
from darthand.model.gestures import model_gestures
from darthand.model.layout import FINGER_JOINTS, FINGERS, NUM_JOINTS
from darthand.model.library_fit import model_library
from darthand.model.pose_library import library_poses, select_tags
from darthand.model.poses import load_pose_file
from darthand.model.rotations import axis_angle_to_quaternion, quaternion_to_axis_angle, slerp

POSE_STREAM = 1
JITTER_STREAM = 2
DEFAULT_LEVELS = 3
DEFAULT_DRAWS = 2000           # DART's K
DEFAULT_STEPS = 8              # DART's slerp steps
DEFAULT_JITTER_DEG = 5.0
DEFAULT_MAX_REFERENCE_MB = 256
FREIHAND_ROW = 61
LIBRARY = "library"            # the reference spec of the pose library (model/pose_library), 'library:TAG,...'
# The axes each digit's grid varies, per joint of the digit (root to tip): hinges bend only, MCPs also spread, the
# thumb's CMC also twists (opposition).
GRID_AXES = {"finger": (("spread", "bend"), ("bend",), ("bend",)),
             "thumb": (("twist", "spread", "bend"), ("bend",), ("bend",))}
_AXIS = {"twist": 0, "spread": 1, "bend": 2}


# ------------------------------------------------------------------------------------------------ reference sets


@dataclass(frozen=True, eq=False)
class ReferenceSet:
    """Reference poses: quats (N, 15, 4) float32, the finger joints' local rotations (w, x, y, z) relative to the
    flat hand; names (N,) for named poses or None; `source` what they came from (for the records)."""

    quats: np.ndarray
    source: str
    names: tuple | None = None

    def __len__(self) -> int:
        return int(self.quats.shape[0])

    def pose(self, k: int) -> np.ndarray:
        """(48,) float64 axis-angle of pose k (root zero)."""
        out = np.zeros(3 * NUM_JOINTS)
        out[3:] = quaternion_to_axis_angle(self.quats[k].astype(np.float64)).reshape(-1)
        return out

    def name(self, k: int) -> str | None:
        return None if self.names is None else self.names[k]


def reference_from_poses(poses: np.ndarray, source: str, names=None) -> ReferenceSet:
    """A ReferenceSet of (N, 48) axis-angle poses relative to the flat hand (their roots are dropped)."""
    poses = np.asarray(poses, np.float64).reshape(len(poses), NUM_JOINTS, 3)
    if not len(poses):
        raise InputError(f"{source}: no poses")
    quats = axis_angle_to_quaternion(poses[:, 1:]).astype(np.float32)
    return ReferenceSet(quats, source, None if names is None else tuple(names))


def load_reference(spec, model, max_mb: float = DEFAULT_MAX_REFERENCE_MB, gestures=None,
                   model_path=None) -> ReferenceSet:
    """The reference set named by `spec`: 'gestures' (or None) for the gesture library on `model` (right hand;
    `gestures`: some of its names), 'library' or 'library:TAG[,TAG]' for the pose library (`library_reference`;
    model_path: the model's file, beside which `make assets` writes the library's fit), or a path to a darthand
    pose file or a FreiHAND training_mano.json. `max_mb`: the largest file read (InputError naming the budget and
    how to raise it otherwise)."""
    if isinstance(spec, str) and (spec == LIBRARY or spec.startswith(LIBRARY + ":")):
        return library_reference(spec, model, gestures, model_path)
    if spec in (None, "gestures"):
        known = model_gestures(model)                      # the model's own (fitted) gestures
        for name in gestures or ():
            if name not in known.names:
                raise InputError(f"poses: {name!r} is not a gesture ({', '.join(known.names)})")
        chosen = model_gestures(model, list(gestures)) if gestures else known
        return reference_from_poses(chosen.poses, "gestures", chosen.names)
    path = Path(str(spec))
    if not path.is_file():
        raise InputError(f"reference poses: {spec!r} is neither 'gestures' nor a file")
    size = path.stat().st_size
    if size > max_mb * 1e6:
        raise InputError(f"{path}: {size / 1e6:.0f} MB is over the reference-file budget of {max_mb:g} MB "
                         "(--max-reference-mb raises it; each MB holds ~800 poses and needs ~30 MB to parse)")
    doc = read_json(path, "reference pose file")
    if isinstance(doc, list):
        return reference_from_poses(freihand_poses(doc, model, str(path)), f"freihand:{path.name}")
    return reference_from_poses(pose_file_vectors_any_betas(model, path), f"file:{path.name}")


def library_reference(spec: str, model, names=None, model_path=None) -> ReferenceSet:
    """The pose library on `model` (its fitted poses when a fit of it is found beside `model_path`, the model's
    file: model/library_fit) as a reference set: 'library', or 'library:TAG[,TAG]' for the poses carrying any of
    the tags (or in any of those groups); `names`: only these poses."""
    tags = [t for t in spec.partition(":")[2].split(",") if t]
    if spec != LIBRARY and not tags:
        raise InputError(f"reference poses: {spec!r} names no tag (library:TAG[,TAG], e.g. library:alphabet)")
    chosen = library_poses()
    chosen = select_tags(chosen, tags) if tags else chosen
    if names:
        known = {p.name for p in chosen}
        for name in names:
            if name not in known:
                raise InputError(f"poses: {name!r} is not a pose of the pose library ({spec}; its names: "
                                 "assets_src/poses/library)")
        chosen = [p for p in chosen if p.name in set(names)]
    lib = model_library(model, poses=chosen, beside=model_path)
    return reference_from_poses(lib.poses, spec, lib.names)


def pose_file_vectors_any_betas(model, path) -> np.ndarray:
    """(N, 48) poses of a darthand pose file relative to the flat hand; betas, if any, are ignored (a reference set
    only needs the articulation)."""
    poses, _, flat_hand_mean = load_pose_file(path)
    poses = np.array(poses, np.float64)
    if not flat_hand_mean:
        poses[:, 3:] += model.hands_mean
    return poses


def freihand_poses(rows: list, model, source: str) -> np.ndarray:
    """(N, 48) poses relative to the flat hand from FreiHAND's training_mano.json rows ([61 numbers] or [[61]]):
    its 48 pose values have MANO's mean hand left out (flat_hand_mean false), so the model's hands_mean is added."""
    out = np.empty((len(rows), 3 * NUM_JOINTS))
    for k, row in enumerate(rows):
        if isinstance(row, list) and len(row) == 1 and isinstance(row[0], list):
            row = row[0]
        if not isinstance(row, list) or len(row) != FREIHAND_ROW:
            got = len(row) if isinstance(row, list) else type(row).__name__
            raise InputError(f"{source}: row {k} has {got} values, a training_mano.json row has {FREIHAND_ROW} "
                             "(48 pose, 10 shape, 2 root uv, 1 scale)")
        try:
            values = np.asarray(row[:48], np.float64)
        except (TypeError, ValueError):
            raise InputError(f"{source}: row {k} holds a value that is not a number") from None
        if not np.isfinite(values).all():
            raise InputError(f"{source}: row {k} holds a non-finite pose value")
        out[k] = values
    if not len(out):
        raise InputError(f"{source}: no rows")
    out[:, 3:] += model.hands_mean
    return out


# ------------------------------------------------------------------------------------------------ samplers


def pose_angle_distance(q_base: np.ndarray, quats: np.ndarray) -> np.ndarray:
    """(K,) sum over the 15 finger joints of the rotation angle (radians) between q_base (15, 4) and each of
    quats (K, 15, 4)."""
    dots = np.abs(np.einsum("kjc,jc->kj", quats.astype(np.float64), q_base))
    return (2 * np.arccos(np.minimum(dots, 1.0))).sum(axis=1)


class GridSlerp:
    """DART's pose sampler (module docstring). model: a right-handed HandModel (its anatomy frames)."""

    def __init__(self, model, reference: ReferenceSet, *, levels: int = DEFAULT_LEVELS, draws: int = DEFAULT_DRAWS,
                 steps: int = DEFAULT_STEPS):
        if not 2 <= int(levels) <= 16:
            raise InputError(f"grid levels: {levels} must be within 2..16")
        if not 1 <= int(draws) <= 100_000:
            raise InputError(f"reference draws: {draws} must be within 1..100000")
        if not 1 <= int(steps) <= 1000:
            raise InputError(f"slerp steps: {steps} must be within 1..1000")
        self.model, self.reference = model, reference
        self.levels, self.draws, self.steps = int(levels), int(draws), int(steps)
        self.frames = joint_frames(model)
        lim = limits_radians()
        # per digit: [(joint, axis, values (levels,))]
        self.axes = {}
        for finger in FINGERS:
            joints = FINGER_JOINTS[finger]
            table = GRID_AXES["thumb" if finger == "thumb" else "finger"]
            self.axes[finger] = [(j, _AXIS[a], np.linspace(lim[j, _AXIS[a], 0], lim[j, _AXIS[a], 1], self.levels))
                                 for j, names in zip(joints, table) for a in names]
        self.cells = {f: self.levels ** len(self.axes[f]) for f in FINGERS}
        self._group: tuple | None = None

    def base_angles(self, cells: dict) -> np.ndarray:
        """(16, 3) anatomical angles of the grid cell {digit: cell index} (mixed-radix digits, one per axis)."""
        angles = np.zeros((NUM_JOINTS, 3))
        for finger, cell in cells.items():
            for j, axis, values in self.axes[finger]:
                cell, digit = divmod(int(cell), self.levels)
                angles[j, axis] = values[digit]
        return angles

    def group(self, seed: int, g: int) -> dict:
        """Group g: {'cells', 'base' (15, 4) quaternions, 'reference' index, 'distance' radians}; the last group is
        kept, so a group's frames (consecutive indices) compute it once."""
        if self._group is not None and self._group[0] == (seed, g):
            return self._group[1]

        rng = np.random.default_rng([seed, POSE_STREAM, g])
        cells = {f: int(rng.integers(self.cells[f])) for f in FINGERS}
        drawn = rng.integers(len(self.reference), size=self.draws)
        base_aa = angles_to_axis_angle(self.model, self.base_angles(cells), self.frames)
        base = axis_angle_to_quaternion(base_aa[1:])
        dist = pose_angle_distance(base, self.reference.quats[drawn])
        best = int(np.argmax(dist))
        result = {"cells": cells, "base": base, "reference": int(drawn[best]), "distance": float(dist[best])}
        self._group = ((seed, g), result)
        return result

    def sample(self, seed: int, index: int) -> tuple[np.ndarray, dict]:
        """((48,) axis-angle pose of frame `index`, its record)."""
        g, k = divmod(int(index), self.steps)
        group = self.group(seed, g)
        t = k / (self.steps - 1) if self.steps > 1 else 0.0
        target = self.reference.quats[group["reference"]].astype(np.float64)
        q = slerp(group["base"], target, np.full(len(target), t))
        pose = np.zeros(3 * NUM_JOINTS)
        pose[3:] = quaternion_to_axis_angle(q).reshape(-1)
        record = {"mode": "dart", "group": g, "step": k, "t": round(t, 6),
                  "base_cells": [group["cells"][f] for f in FINGERS],
                  "reference": {"set": self.reference.source, "index": group["reference"],
                                "name": self.reference.name(group["reference"])},
                  "distance_deg": round(math.degrees(group["distance"]), 3)}
        return pose, record


class GestureJitter:
    """Reference poses (gestures by default) perturbed per finger joint and axis by a Gaussian of `jitter_deg`,
    clipped to the joint limits (widened to the unperturbed angle where that lies outside them)."""

    def __init__(self, model, reference: ReferenceSet, jitter_deg: float = DEFAULT_JITTER_DEG):
        if not (math.isfinite(float(jitter_deg)) and 0 <= float(jitter_deg) <= 45):
            raise InputError(f"pose jitter: {jitter_deg} degrees is outside 0..45")
        self.model, self.reference, self.jitter = model, reference, math.radians(float(jitter_deg))
        self.frames, self.limits = joint_frames(model), limits_radians()

    def sample(self, seed: int, index: int) -> tuple[np.ndarray, dict]:
        rng = np.random.default_rng([seed, JITTER_STREAM, int(index)])
        k = int(rng.integers(len(self.reference)))
        noise = rng.standard_normal((NUM_JOINTS - 1, 3))
        pose = self.reference.pose(k)
        if self.jitter:
            base = axis_angle_to_angles(self.model, pose, self.frames)
            lim = self.limits[1:]
            lo, hi = np.minimum(lim[..., 0], base[1:]), np.maximum(lim[..., 1], base[1:])
            angles = base.copy()
            angles[1:] = np.clip(base[1:] + self.jitter * noise, lo, hi)
            pose = angles_to_axis_angle(self.model, angles, self.frames).reshape(-1)
            pose[:3] = 0.0
        record = {"mode": "jitter", "jitter_deg": round(math.degrees(self.jitter), 6),
                  "reference": {"set": self.reference.source, "index": k, "name": self.reference.name(k)}}
        return pose, record


class GestureNames:
    """A USD package's baked gestures, by name, drawn uniformly (a USD package cannot take pose vectors)."""

    def __init__(self, names: list[str]):
        if not names:
            raise InputError("poses: the package has no gestures")
        self.names = list(names)

    def sample(self, seed: int, index: int) -> tuple[str, dict]:
        rng = np.random.default_rng([seed, JITTER_STREAM, int(index)])
        k = int(rng.integers(len(self.names)))
        return self.names[k], {"mode": "gestures", "reference": {"set": "package", "index": k,
                                                                 "name": self.names[k]}}

