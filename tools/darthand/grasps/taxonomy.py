"""The grasp taxonomy: a subset of Feix et al.'s 33 grasp types (The GRASP Taxonomy of Human Grasp Types, 2016),
each a pre-shape in anatomical angles with the contact parts it closes onto an object and the object categories
it suits. Read from assets_src/poses/library/grasps.json (the pose library's format, plus a `grasp` block)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import read_json
from darthand.model.anatomy import AXES, LIMITS
from darthand.model.layout import JOINT_NAMES, NUM_JOINTS
from darthand.model.poses import POSES_DIR

GRASPS_FILE = POSES_DIR / "library" / "grasps.json"
KINDS = ("power", "intermediate", "precision")
OPPOSITIONS = ("palm", "pad", "side")


@dataclass(frozen=True)
class GraspType:
    """One grasp type: name (snake_case of Feix's), feix number (1..33), kind, opposition, contact part names
    (see grasps/parts.py), the object categories it suits, its pre-shape `angles` (16, 3) radians, and
    `across_deg`: its knuckle line's angle to the object's axis, degrees (0: along it, a wrap round a handle)."""

    name: str
    feix: int
    kind: str
    opposition: str
    contacts: tuple[str, ...]
    categories: tuple[str, ...]
    angles: np.ndarray
    across_deg: float = 0.0


def load_taxonomy(path: str | Path | None = None) -> dict[str, GraspType]:
    """The grasp types of grasps.json (default the shipped one), by name, in file order."""
    path = Path(GRASPS_FILE if path is None else path)
    doc = read_json(path, "grasp taxonomy")
    out: dict[str, GraspType] = {}
    for k, pose in enumerate(doc.get("poses", [])):
        where = f"{path}: poses[{k}]"
        if "grasp" not in pose:
            continue
        g = pose["grasp"]
        if pose["name"] in out:
            raise InputError(f"{where}: grasp {pose['name']!r} is named twice")
        if g.get("type") not in KINDS or g.get("opposition") not in OPPOSITIONS:
            raise InputError(f"{where}: grasp.type or grasp.opposition is not one of {KINDS} / {OPPOSITIONS}")
        out[pose["name"]] = GraspType(pose["name"], int(g["feix"]), g["type"], g["opposition"],
                                      tuple(g["contacts"]), tuple(g["categories"]),
                                      joints_to_angles(pose.get("joints", {}), where),
                                      float(g.get("across_deg", 0.0)))
    return out


def joints_to_angles(joints: dict, where: str) -> np.ndarray:
    """(16, 3) radians from the gesture files' layout {joint: {twist|spread|bend: degrees}}, checked against the
    joint limits (model/anatomy.LIMITS)."""
    angles = np.zeros((NUM_JOINTS, 3))
    for joint, values in joints.items():
        if joint not in JOINT_NAMES:
            raise InputError(f"{where}: joint {joint!r} is not one of MANO's joint names")
        for axis, deg in values.items():
            k = AXES.index(axis)
            lo, hi = LIMITS[joint][k]
            if not (np.isfinite(deg) and lo <= deg <= hi):
                raise InputError(f"{where}: joints.{joint}.{axis} is {deg} deg, outside the limit {lo}..{hi}")
            angles[JOINT_NAMES.index(joint), k] = np.deg2rad(deg)
    return angles


def types_for(item, taxonomy: dict[str, GraspType]) -> tuple[list[str], list[str]]:
    """(known, unknown) grasp type names for an object: its catalogue `grasps` list, or, when that is empty, the
    types whose categories include the object's category."""
    names = list(getattr(item, "grasps", ()) or ())
    if not names:
        names = [n for n, t in taxonomy.items() if item.category in t.categories]
    return [n for n in names if n in taxonomy], [n for n in names if n not in taxonomy]
