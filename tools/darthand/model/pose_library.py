"""The pose library: named, tagged hand poses in anatomical angles (assets_src/poses/library/<group>.json, CC0).

A group file holds

    {"group": "alphabet", "description": "...", "licence": "CC0-1.0",
     "poses": [{"name": "asl_a", "tags": ["alphabet", ...], "description": "...",
                "joints": {"index1": {"bend": 80}, "thumb1": {"twist": 0, "spread": 10, "bend": 20}, ...},
                "contacts": [["thumb", "index"]],          # optional: parts the pose means to touch
                "grasp": {...}}]}                           # grasps.json only (the grasp stage's pre-shapes)

with `joints` in the gesture files' layout (joint -> twist/spread/bend degrees, omitted = 0) and every angle within
model/anatomy's limits. The 12 gestures of assets_src/poses join the built-in library as the group 'gestures'.
Names are unique across the library. `library_poses()` reads and checks it; `select_tags` picks a tagged subset.
How the library is fitted to a model and read back per model is model/library_fit.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import read_json
from darthand.model.anatomy import AXES, LIMITS
from darthand.model.layout import FINGERS, JOINT_NAMES, NUM_JOINTS
from darthand.model.poses import POSES_DIR, gesture_angles, gesture_contacts, list_gestures

LIBRARY_DIR = POSES_DIR / "library"
GESTURES_GROUP = "gestures"
NAME = re.compile(r"^[a-z][a-z0-9_]*$")
GROUP_FIELDS = {"group", "description", "licence", "poses"}
POSE_FIELDS = {"name", "tags", "description", "joints", "contacts", "grasp"}
PARTS = ("palm",) + FINGERS     # model/intersections.PARTS, without importing MeshLab


@dataclass(frozen=True, eq=False)
class LibraryPose:
    """One library pose. angles (16, 3) radians [twist, spread, bend] per MANO joint; contacts: pairs of part
    names (model/intersections.PARTS) the pose means to touch; grasp: grasps.json's block or None."""

    name: str
    group: str
    tags: tuple[str, ...]
    description: str
    angles: np.ndarray
    grasp: dict | None = None
    contacts: tuple[tuple[str, str], ...] = field(default_factory=tuple)


def library_poses(directory: str | Path | None = None, gestures: bool | None = None) -> list[LibraryPose]:
    """Every pose of every group file in `directory` (default assets_src/poses/library), groups in file-name
    order, poses in file order; with `gestures` (default: when reading the built-in library) the named gestures
    of assets_src/poses first, as the group 'gestures'. InputError naming the file, pose and field of the first
    problem: an unknown joint or axis, an angle outside its limit, a name used twice."""
    folder = Path(LIBRARY_DIR if directory is None else directory)
    if not folder.is_dir():
        raise InputError(f"{folder}: no such pose library folder")
    out = gesture_group() if (directory is None if gestures is None else gestures) else []
    seen = {p.name: f"{POSES_DIR}/{p.name}.json" for p in out}
    for path in sorted(folder.glob("*.json")):
        for pose in read_group(path):
            if pose.name in seen:
                raise InputError(f"{path}: pose {pose.name!r} is also in {seen[pose.name]}: names are unique "
                                 "across the library")
            seen[pose.name] = str(path)
            out.append(pose)
    return out


def gesture_group() -> list[LibraryPose]:
    """The named gestures of assets_src/poses as library poses (group 'gestures', tagged 'gesture')."""
    return [LibraryPose(name, GESTURES_GROUP, ("gesture", name), f"the named gesture {name}", gesture_angles(name),
                        None, tuple((a, b) for a, b in gesture_contacts(name))) for name in list_gestures()]


def read_group(path: Path) -> list[LibraryPose]:
    """The poses of one group file, checked (see `library_poses`)."""
    doc = read_json(path, "pose library file")
    if not isinstance(doc, dict):
        raise InputError(f"{path}: the document is {type(doc).__name__}, expected an object")
    extra = sorted(set(doc) - GROUP_FIELDS)
    if extra:
        raise InputError(f"{path}: field {extra[0]!r} is not an allowed field ({', '.join(sorted(GROUP_FIELDS))})")
    for key in ("group", "licence"):
        if not isinstance(doc.get(key), str) or not doc[key]:
            raise InputError(f"{path}: field '{key}' is missing or not a string")
    if not isinstance(doc.get("poses"), list) or not doc["poses"]:
        raise InputError(f"{path}: field 'poses' is missing or empty")
    group, names = doc["group"], set()
    out = []
    for k, entry in enumerate(doc["poses"]):
        pose = read_pose(path, k, entry, group)
        if pose.name in names:
            raise InputError(f"{path}: pose {pose.name!r} appears twice")
        names.add(pose.name)
        out.append(pose)
    return out


def read_pose(path: Path, k: int, entry, group: str) -> LibraryPose:
    """poses[k] of a group file as a LibraryPose, checked."""
    where = f"{path}: poses[{k}]"
    if not isinstance(entry, dict):
        raise InputError(f"{where} is {type(entry).__name__}, expected an object")
    name = entry.get("name")
    if not isinstance(name, str) or not NAME.match(name):
        raise InputError(f"{where}: field 'name' is {name!r}, expected lower_snake_case")
    where = f"{path}: pose {name!r}"
    extra = sorted(set(entry) - POSE_FIELDS)
    if extra:
        raise InputError(f"{where}: field {extra[0]!r} is not an allowed field")
    tags = entry.get("tags", [])
    if not isinstance(tags, list) or not all(isinstance(t, str) and NAME.match(t) for t in tags):
        raise InputError(f"{where}: field 'tags' is not a list of lower_snake_case words")
    grasp = entry.get("grasp")
    if grasp is not None and not isinstance(grasp, dict):
        raise InputError(f"{where}: field 'grasp' is not an object")
    return LibraryPose(name, group, tuple(tags), str(entry.get("description", "")),
                       joint_angles(where, entry.get("joints")), grasp, pose_contacts(where, entry.get("contacts", [])))


def joint_angles(where: str, joints) -> np.ndarray:
    """(16, 3) radians from the {joint: {axis: degrees}} layout; InputError naming an unknown joint or axis, a
    value that is not a number, or one outside its joint limit."""
    if not isinstance(joints, dict):
        raise InputError(f"{where}: field 'joints' is missing or not an object")
    angles = np.zeros((NUM_JOINTS, 3))
    for joint, values in joints.items():
        if joint not in JOINT_NAMES:
            raise InputError(f"{where}: unknown joint {joint!r} (joints are {', '.join(JOINT_NAMES)})")
        if not isinstance(values, dict):
            raise InputError(f"{where}: field 'joints.{joint}' is not an object of axis angles")
        for axis, deg in values.items():
            if axis not in AXES:
                raise InputError(f"{where}: field 'joints.{joint}.{axis}' is not an axis ({', '.join(AXES)})")
            if isinstance(deg, bool) or not isinstance(deg, (int, float)) or not np.isfinite(deg):
                raise InputError(f"{where}: field 'joints.{joint}.{axis}' is {deg!r}, expected degrees")
            lo, hi = LIMITS[joint][AXES.index(axis)]
            if not lo <= deg <= hi:
                raise InputError(f"{where}: field 'joints.{joint}.{axis}' is {deg} deg, outside the joint limit "
                                 f"{lo}..{hi}")
            angles[JOINT_NAMES.index(joint), AXES.index(axis)] = np.deg2rad(deg)
    return angles


def pose_contacts(where: str, contacts) -> tuple[tuple[str, str], ...]:
    """The pose's contact pairs, checked: two different part names each."""
    ok = isinstance(contacts, list) and all(isinstance(c, list) and len(c) == 2 and c[0] != c[1]
                                            and set(c) <= set(PARTS) for c in contacts)
    if not ok:
        raise InputError(f"{where}: field 'contacts' is not a list of pairs of different parts ({', '.join(PARTS)})")
    return tuple((a, b) for a, b in contacts)


def select_tags(poses: list[LibraryPose], tags: list[str] | tuple[str, ...]) -> list[LibraryPose]:
    """The poses carrying any of `tags` (a tag is also matched by a group's name); InputError naming a tag no pose
    carries."""
    known = {t for p in poses for t in p.tags} | {p.group for p in poses}
    for tag in tags:
        if tag not in known:
            raise InputError(f"pose library: no pose is tagged {tag!r} (tags: {', '.join(sorted(known))})")
    wanted = set(tags)
    return [p for p in poses if wanted & (set(p.tags) | {p.group})]
