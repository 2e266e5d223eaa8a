"""The pose library fitted to one model, and the library as a model poses it.

`fit_library(model)` fits every library pose (model/pose_library) as the gestures are fitted (model/gesture_fit:
the authored angles changed as little as the model needs so no digit passes through another and intended contacts
touch) and returns a record (FIT_FORMAT) that `make assets` writes to build/poses/right.json, a step of its own
beside the model's (the model build, and everything after it, does not wait for ~140 fits). The left model is the
right one's mirror and anatomical angles are mirror-symmetric, so that one fit serves both sides (`model_digest`).

`model_library(model)` is the library on a model: the fitted angles when a fit of this very model is found (the
record names the model's geometry digest; found beside the model file, build/poses/right.json for
build/model/<side>.npz, or named), else the authored angles, as a model without a gesture record gets the authored
gestures. DART's sampler draws its poses for the right-handed twin of each source (dataset/poses), so the right fit
is the one datasets use.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from darthand.errors import InputError
from darthand.fileio import atomic_path, read_json
from darthand.model.anatomy import angles_to_axis_angle, joint_frames
from darthand.model.gestures import angles_to_joints, joints_to_angles
from darthand.model.hand_model import HandModel
from darthand.model.layout import NUM_JOINTS
from darthand.model.pose_library import LibraryPose, library_poses

FIT_FORMAT = "darthand-fitted-pose-library"
FIT_VERSION = 1
FIT_FOLDER = "poses"            # build/poses/right.json beside build/model/right.npz


@dataclass(frozen=True, eq=False)
class ModelLibrary:
    """The library on one model: names (N,), groups (N,), tags (N,) tuples, angles (N, 16, 3) radians, poses
    (N, 48) MANO axis-angle on the model (flat_hand_mean=True); fitted: the angles are a fit to this model."""

    names: tuple[str, ...]
    groups: tuple[str, ...]
    tags: tuple[tuple[str, ...], ...]
    angles: np.ndarray
    poses: np.ndarray
    fitted: bool

    def subset(self, keep: list[int]) -> ModelLibrary:
        """The poses at indices `keep`, in that order."""
        return ModelLibrary(tuple(self.names[k] for k in keep), tuple(self.groups[k] for k in keep),
                            tuple(self.tags[k] for k in keep), self.angles[keep], self.poses[keep], self.fitted)


def model_digest(model: HandModel) -> str:
    """sha256 (hex, 16 characters) of what a fit depends on, the right-handed twin's rest vertices and faces: a
    left model (the x -> -x mirror of a right one, model/mirror) has its right twin's digest, since the library's
    angles are mirror-symmetric and one fit serves both sides."""
    v, f = np.asarray(model.v_template, np.float64), np.asarray(model.faces, np.int64)
    if model.side == "left":
        v, f = v * np.array([-1.0, 1.0, 1.0]), f[:, [0, 2, 1]]
    h = hashlib.sha256(np.ascontiguousarray(v).tobytes())
    h.update(np.ascontiguousarray(f).tobytes())
    return h.hexdigest()[:16]


# ------------------------------------------------------------------------------------------------ fit


def fit_library(model: HandModel, poses: list[LibraryPose] | None = None, progress=None) -> dict:
    """The record of the library (default: all of it) fitted to `model`: per pose its fitted angles ('joints', the
    pose files' layout), status ('kept', 'fitted', 'unresolved'), what changed (degrees), the digit pairs still
    crossing and the seconds it took. progress: called with (done, total) after each pose."""
    # MeshLab and the proximity queries load only for a fit (the sampler reads fits without them).
    from darthand.model.gesture_fit import CLEARANCE, CONTACT_GAP, MAX_CHANGE_DEG, ROUNDS, fit_gesture
    from darthand.model.intersections import face_parts   # MeshLab: only for a fit
    from darthand.model.proximity import PartSurfaces     # the fit's distances: only for a fit

    poses = library_poses() if poses is None else poses
    surfaces, frames, face_part = PartSurfaces(model), joint_frames(model), face_parts(model)
    out = {}
    start = time.perf_counter()
    for k, pose in enumerate(poses):
        t0 = time.perf_counter()
        with threadpool_limits(limits=1, user_api="blas"):   # small products: threaded BLAS only spin-waits
            r = fit_gesture(model, surfaces, frames, pose.name, pose.angles, list(pose.contacts), face_part)
        out[pose.name] = {"joints": angles_to_joints(r.angles), "status": r.status, "changed_deg": r.changed,
                          "max_change_deg": round(max(map(abs, r.changed.values()), default=0.0), 3),
                          "crossing": r.crossing, "seconds": round(time.perf_counter() - t0, 3)}
        if progress is not None:
            progress(k + 1, len(poses))
    return {"format": FIT_FORMAT, "version": FIT_VERSION, "model": {"side": model.side,
                                                                     "digest": model_digest(model),
                                                                     "source": str(model.meta.get("source", ""))},
            "settings": {"clearance_mm": CLEARANCE * 1e3, "contact_gap_mm": CONTACT_GAP * 1e3, "rounds": ROUNDS,
                         "max_change_deg": MAX_CHANGE_DEG},
            "seconds": round(time.perf_counter() - start, 2), "poses": out}


def write_fit(path: str | Path, record: dict) -> None:
    """Write a fit record as JSON, atomically."""
    with atomic_path(path) as tmp:
        Path(tmp).write_text(json.dumps(record, indent=1) + "\n")


def read_fit(path: str | Path) -> dict:
    """A fit record, checked for its format; InputError naming the file otherwise."""
    record = read_json(Path(path), "fitted pose library")
    if not isinstance(record, dict) or record.get("format") != FIT_FORMAT:
        raise InputError(f"{path}: not a {FIT_FORMAT} record")
    if int(record.get("version", 0)) > FIT_VERSION:
        raise InputError(f"{path}: field 'version' is {record['version']}, this darthand reads up to {FIT_VERSION}")
    if not isinstance(record.get("poses"), dict):
        raise InputError(f"{path}: field 'poses' is missing")
    return record


# ------------------------------------------------------------------------------------------------ read back


def model_library(model: HandModel, fit: str | Path | None = None, poses: list[LibraryPose] | None = None,
                  beside: str | Path | None = None) -> ModelLibrary:
    """The library (default: all of it) on `model`: its fitted angles from `fit` (a fit record's path: InputError
    when it is another model's or misses a pose), else from the fit `make assets` writes beside the model file
    `beside` (build/poses/right.json for build/model/<side>.npz; used when it is this model's or its mirror's),
    else the authored angles."""
    poses = library_poses() if poses is None else poses
    path, record = _fit_record(model, fit, beside)
    angles = np.stack([p.angles for p in poses]) if poses else np.zeros((0, NUM_JOINTS, 3))
    if record is not None:
        fitted = record["poses"]
        missing = [p.name for p in poses if p.name not in fitted]
        if missing:
            raise InputError(f"{path}: no fit of pose {missing[0]!r} (refit the library: `darthand model "
                             "fit-library`)")
        angles = np.stack([joints_to_angles(fitted[p.name]["joints"]) for p in poses])
    out = angles_to_axis_angle(model, angles, joint_frames(model)).reshape(len(poses), 3 * NUM_JOINTS)
    return ModelLibrary(tuple(p.name for p in poses), tuple(p.group for p in poses), tuple(p.tags for p in poses),
                        angles, out, record is not None)


def fit_beside(model_path: str | Path | None) -> Path | None:
    """Where `make assets` writes the fit of the model file `model_path`: <its folder>/../poses/right.json
    (build/model/right.npz -> build/poses/right.json), None for no path."""
    if model_path is None:
        return None
    return Path(str(model_path)).parent.parent / FIT_FOLDER / "right.json"


def _fit_record(model: HandModel, fit: str | Path | None,
                beside: str | Path | None) -> tuple[Path | None, dict | None]:
    """(path, record) of the fit to use on `model`: `fit`'s (InputError when it is missing or another model's),
    or the one beside the model file when it is this model's, or (None, None)."""
    if fit is not None:
        path = Path(fit)
        if not path.is_file():
            raise InputError(f"{path}: no such fitted pose library")
        record = read_fit(path)
        if record.get("model", {}).get("digest") != model_digest(model):
            raise InputError(f"{path}: fitted to another model (digest {record.get('model', {}).get('digest')}, "
                             f"this model's {model_digest(model)})")
        return path, record
    found = fit_beside(beside)
    if found is None or not found.is_file():
        return None, None
    record = read_fit(found)
    return (found, record) if record.get("model", {}).get("digest") == model_digest(model) else (None, None)
