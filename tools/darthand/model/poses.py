"""Pose files: named gestures (anatomical angles) and MANO pose vectors, both under schemas/pose.schema.json.

A gesture (assets_src/poses/<name>.json) is written in degrees per joint and axis, e.g.

    {"name": "point", "joints": {"middle1": {"bend": 80}, "middle2": {"bend": 95}, ...}}

and becomes a MANO pose vector for a particular model at load time (`load_gesture`), through the model's own joint
frames (`anatomy.angles_to_axis_angle`), so the same file poses MANO, the open hand and their left mirrors alike.
A pose file (`darthand model pose --pose POSE.json`) holds axis-angle vectors directly (`load_pose_file`).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import jsonschema
import numpy as np

from darthand.errors import InputError
from darthand.fileio import read_json
from darthand.model.anatomy import AXES, LIMITS, angles_to_axis_angle
from darthand.model.forward import MAX_MAGNITUDE
from darthand.model.hand_model import HandModel
from darthand.model.layout import JOINT_NAMES, NUM_JOINTS
from darthand.schemas import load_schema

REPO_ROOT = Path(__file__).resolve().parents[3]
POSES_DIR = REPO_ROOT / "assets_src" / "poses"


def _validator(kind: str) -> jsonschema.protocols.Validator:
    """A validator for one of the schema's definitions ('gesture' or 'pose_file')."""
    schema = load_schema("pose.schema.json")
    sub = dict(schema["$defs"][kind], **{"$defs": schema["$defs"]})
    return jsonschema.Draft202012Validator(sub)


def _check_schema(path: Path, doc, kind: str) -> None:
    """Raise InputError naming the file and the field of the most relevant schema violation."""
    error = jsonschema.exceptions.best_match(_validator(kind).iter_errors(doc))
    if error is None:
        return
    while error.parent is not None and error.parent.validator in ("oneOf", "anyOf"):
        error = error.parent
    field, msg = _describe(_within_branch(error))
    raise InputError(f"{path}: field '{field}' {msg}" if field else f"{path}: the document {msg}")


def _describe(error: jsonschema.ValidationError) -> tuple[str, str]:
    """(field, one-line message) of a schema violation, in the words of the pose files."""
    field, instance = _field_name(error.absolute_path), error.instance
    if error.validator in ("minItems", "maxItems") and isinstance(instance, list):
        lo, hi = error.schema.get("minItems"), error.schema.get("maxItems")
        want = f"{lo}" if lo == hi else (f"at least {lo}" if error.validator == "minItems" else f"at most {hi}")
        return field, f"has {len(instance)} values, expected {want}"
    if error.validator == "type":
        return field, f"is {type(instance).__name__} {_short(instance)}, expected {error.validator_value}"
    if error.validator == "required":
        missing = [k for k in error.validator_value if k not in instance]
        return _field_name(list(error.absolute_path) + missing[:1]), "is missing"
    if error.validator == "additionalProperties":
        extra = sorted(set(instance) - set(error.schema.get("properties", {})))
        return _field_name(list(error.absolute_path) + extra[:1]), "is not an allowed field"
    if "propertyNames" in error.relative_schema_path:
        return field, f"has an unknown joint name {instance!r} (joints are {', '.join(JOINT_NAMES)})"
    return field, _short(error.message, 120)


def _within_branch(error: jsonschema.ValidationError) -> jsonschema.ValidationError:
    """For a oneOf/anyOf failure, the first error of the alternative that failed least (the one the author
    most likely meant: a 47-number pose is a short pose vector, not a batch of 47 non-vectors)."""
    while error.validator in ("oneOf", "anyOf") and error.context:
        branches: dict[int, list] = {}
        for e in error.context:
            branches.setdefault(e.relative_schema_path[0], []).append(e)
        error = min(branches.values(), key=len)[0]
    return error


def _field_name(parts) -> str:
    """'pose[2][5]' / 'joints.index1.bend' from a jsonschema path."""
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


def _short(x, n: int = 40) -> str:
    """x in at most n characters on one line (a string's repr when it holds a line break)."""
    s = x if isinstance(x, str) and x.isprintable() else repr(x)
    return s if len(s) <= n else s[:n - 3] + "..."


def _check_finite(path: Path, field: str, arr: np.ndarray) -> None:
    """Every value finite and within the forward pass's bound for the field (radians for poses)."""
    limit = MAX_MAGNITUDE[field]
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(arr) <= limit)
    if bad.any():
        idx = np.unravel_index(int(np.argmax(bad)), arr.shape)
        where = "".join(f"[{int(i)}]" for i in idx)
        raise InputError(f"{path}: field '{field}{where}' is {arr[idx]}, expected a finite number within "
                         f"+-{limit:g}")


# ------------------------------------------------------------------------------------------------ pose files


def load_pose_file(path: str | Path) -> tuple[np.ndarray, np.ndarray | None, bool]:
    """Read a MANO pose file: (pose (B, 48) float64 axis-angle, betas (S,) or (B, S) or None, flat_hand_mean).

    Raises InputError naming the file and field on bad JSON, wrong lengths, NaN/Infinity, unknown fields.
    """
    path = Path(path)
    doc = read_json(path, "pose file")
    _check_schema(path, _structure(doc), "pose_file")
    raw = np.asarray(doc["pose"], dtype=np.float64)
    _check_finite(path, "pose", raw)
    pose = np.atleast_2d(raw)
    betas = None
    if "betas" in doc:
        rows = doc["betas"]
        if rows and isinstance(rows[0], list) and len({len(b) for b in rows}) > 1:
            raise InputError(f"{path}: field 'betas' rows have different lengths {sorted({len(b) for b in rows})}")
        betas = np.asarray(rows, dtype=np.float64)
        _check_finite(path, "betas", betas)
        if betas.ndim == 2 and betas.shape[0] not in (1, pose.shape[0]):
            raise InputError(f"{path}: field 'betas' has {betas.shape[0]} rows for {pose.shape[0]} poses")
    return pose, betas, bool(doc.get("flat_hand_mean", True))


def _structure(doc):
    """The document to check against the schema: a batch of poses (or betas) that is a plain (N, k) table of numbers
    is represented by its first row, so a file of a million poses is not checked number by number by jsonschema
    (minutes); anything less regular is checked whole, for the schema's message naming the bad entry."""
    if not isinstance(doc, dict):
        return doc
    out = dict(doc)
    for key in ("pose", "betas"):
        rows = doc.get(key)
        if isinstance(rows, list) and len(rows) > 1 and _plain_table(rows):
            out[key] = rows[:1]
    return out


def _plain_table(rows: list) -> bool:
    """Every row a list of the same length holding only ints and floats (no bools, strings or nested lists); C-level
    iteration, so a million rows take a fraction of a second."""
    if set(map(type, rows)) != {list} or len(set(map(len, rows))) != 1:
        return False
    return set(map(type, itertools.chain.from_iterable(rows))) <= {int, float}


# ------------------------------------------------------------------------------------------------ gestures


def list_gestures(poses_dir: str | Path | None = None) -> list[str]:
    """Names of the gestures in `poses_dir` (default assets_src/poses), sorted."""
    return sorted(p.stem for p in Path(POSES_DIR if poses_dir is None else poses_dir).glob("*.json"))


def gesture_angles(name: str, poses_dir: str | Path | None = None) -> np.ndarray:
    """(16, 3) anatomical angles [twist, spread, bend] in radians of a named gesture, checked against the schema
    and the joint limits."""
    path, doc = _gesture_doc(name, poses_dir)
    angles = np.zeros((NUM_JOINTS, 3))
    for joint, values in doc["joints"].items():
        j = JOINT_NAMES.index(joint)
        for axis, deg in values.items():
            k = AXES.index(axis)
            lo, hi = LIMITS[joint][k]
            if not (np.isfinite(deg) and lo <= deg <= hi):
                raise InputError(f"{path}: field 'joints.{joint}.{axis}' is {deg} deg, outside the joint limit "
                                 f"{lo}..{hi}")
            angles[j, k] = np.deg2rad(deg)
    return angles


def gesture_contacts(name: str, poses_dir: str | Path | None = None) -> list[tuple[str, str]]:
    """The parts a named gesture means to touch (its `contacts`: pairs of 'palm' or digit names), [] if none."""
    path, doc = _gesture_doc(name, poses_dir)
    pairs = [tuple(pair) for pair in doc.get("contacts", [])]
    for k, (a, b) in enumerate(pairs):
        if a == b:
            raise InputError(f"{path}: field 'contacts[{k}]' pairs {a!r} with itself")
    return pairs


def _gesture_doc(name: str, poses_dir: str | Path | None) -> tuple[Path, dict]:
    """(path, document) of a named gesture, checked against the schema."""
    folder = Path(POSES_DIR if poses_dir is None else poses_dir)
    path = folder / f"{name}.json"
    if not path.is_file():
        raise InputError(f"{path}: no such gesture (known: {', '.join(list_gestures(folder)) or 'none'})")
    doc = read_json(path, "pose file")
    _check_schema(path, doc, "gesture")
    if doc["name"] != path.stem:
        raise InputError(f"{path}: field 'name' is {doc['name']!r}, expected the file name {path.stem!r}")
    return path, doc


def load_gesture(name: str, model: HandModel, poses_dir: str | Path | None = None) -> np.ndarray:
    """(48,) MANO axis-angle pose of a named gesture on `model` (relative to the flat hand: flat_hand_mean=True)."""
    return angles_to_axis_angle(model, gesture_angles(name, poses_dir)).reshape(3 * NUM_JOINTS)


def gesture_poses(model: HandModel, names: list[str] | None = None,
                  poses_dir: str | Path | None = None) -> tuple[list[str], np.ndarray]:
    """(names, (G, 48) poses) of the given gestures, all of them by default."""
    names = list_gestures(poses_dir) if names is None else list(names)
    angles = np.stack([gesture_angles(n, poses_dir) for n in names]) if names else np.zeros((0, NUM_JOINTS, 3))
    return names, angles_to_axis_angle(model, angles).reshape(len(names), 3 * NUM_JOINTS)
