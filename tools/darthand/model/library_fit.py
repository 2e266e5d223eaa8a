"""The pose library fitted to one model, and the library as a model poses it.

`fit_library(model)` fits every library pose (model/pose_library) as the gestures are fitted (model/gesture_fit:
the authored angles changed as little as the model needs so no digit passes through another and intended contacts
touch) and returns a record (FIT_FORMAT) that `make assets` writes to build/poses/right.json, a step of its own
beside the model's (the model build, and everything after it, does not wait for ~140 fits). The left model is the
right one's mirror and anatomical angles are mirror-symmetric, so that one fit serves both sides (`model_digest`).

A fit is cheap to repeat: each pose's entry carries `key`, the fingerprint of everything its fit depends on (the
model's digest, the pose's authored angles and contacts, the fit's settings and the source of the modules that fit
it), and `fit_library(..., previous=record)` takes the entry of an earlier record whose key matches instead of
fitting again (`make assets` passes the record it is replacing, so editing one library pose, or any model code
the fit does not run, refits only what changed); the poses left to fit run in `jobs` processes.

`model_library(model)` is the library on a model: the fitted angles when a fit of this very model is found (the
record names the model's geometry digest; found beside the model file, build/poses/right.json for
build/model/<side>.npz, or named), else the authored angles, as a model without a gesture record gets the authored
gestures. DART's sampler draws its poses for the right-handed twin of each source (dataset/poses), so the right fit
is the one datasets use.
"""

from __future__ import annotations

import concurrent.futures as cf
import functools
import hashlib
import json
import multiprocessing
import os
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
from darthand.processes import deaf_to_ctrl_c, init_worker

FIT_FORMAT = "darthand-fitted-pose-library"
FIT_VERSION = 1
FIT_FOLDER = "poses"            # build/poses/right.json beside build/model/right.npz
# The modules whose code decides a fit's result (a pose's `key` covers their source: editing one refits).
FIT_MODULES = ("anatomy", "forward", "gesture_fit", "gestures", "hand_model", "intersections", "layout",
               "library_fit", "proximity", "topology")


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


def fit_library(model: HandModel, poses: list[LibraryPose] | None = None, progress=None, jobs: int = 1,
                previous: dict | None = None) -> dict:
    """The record of the library (default: all of it) fitted to `model`: per pose its fitted angles ('joints', the
    pose files' layout), status ('kept', 'fitted', 'unresolved'), what changed (degrees), the digit pairs still
    crossing, the seconds it took and its `key` (pose_key). An entry of `previous` (an earlier record) with the same
    key is taken as it is; the other poses are fitted in `jobs` processes. progress: called with (done, total)
    after each pose."""
    from darthand.model.gesture_fit import CLEARANCE, CONTACT_GAP, MAX_CHANGE_DEG, ROUNDS   # with the fit's imports

    poses = library_poses() if poses is None else poses
    start = time.perf_counter()
    prefix = key_prefix(model)
    keys = {p.name: _pose_key(prefix, p) for p in poses}
    reused = {p.name: (previous or {}).get("poses", {}).get(p.name) for p in poses}
    out = {p.name: reused[p.name] for p in poses
           if isinstance(reused[p.name], dict) and reused[p.name].get("key") == keys[p.name]}
    todo = [p for p in poses if p.name not in out]
    for k, (name, entry) in enumerate(_fit_poses(model, todo, jobs)):
        out[name] = entry | {"key": keys[name]}
        if progress is not None:
            progress(len(poses) - len(todo) + k + 1, len(poses))
    return {"format": FIT_FORMAT, "version": FIT_VERSION, "model": {"side": model.side,
                                                                     "digest": model_digest(model),
                                                                     "source": str(model.meta.get("source", ""))},
            "settings": {"clearance_mm": CLEARANCE * 1e3, "contact_gap_mm": CONTACT_GAP * 1e3, "rounds": ROUNDS,
                         "max_change_deg": MAX_CHANGE_DEG},
            "seconds": round(time.perf_counter() - start, 2), "reused": len(poses) - len(todo),
            "poses": {p.name: out[p.name] for p in poses}}


def pose_key(model: HandModel, pose: LibraryPose) -> str:
    """sha256 (hex, 16 characters) of what one pose's fit depends on: the model's digest, the pose's authored angles
    (radians, float64) and contacts, FIT_VERSION and the source of the FIT_MODULES."""
    return _pose_key(key_prefix(model), pose)


def key_prefix(model: HandModel) -> str:
    """What every pose's key shares for `model`: FIT_VERSION, the model's digest, the fit code's digest."""
    return f"{FIT_VERSION} {model_digest(model)} {fit_code_digest()}"


def _pose_key(prefix: str, pose: LibraryPose) -> str:
    h = hashlib.sha256(prefix.encode())
    h.update(np.ascontiguousarray(pose.angles, np.float64).tobytes())
    h.update(json.dumps(sorted(sorted(c) for c in pose.contacts)).encode())
    return h.hexdigest()[:16]


@functools.cache
def fit_code_digest() -> str:
    """sha256 (hex) of the FIT_MODULES' source files, read once per process."""
    folder = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for name in FIT_MODULES:
        h.update((folder / f"{name}.py").read_bytes())
    return h.hexdigest()


def _fit_poses(model: HandModel, poses: list[LibraryPose], jobs: int):
    """(name, entry without its key) of each pose fitted to `model`, in order; in `jobs` processes (spawned, each
    building the model's part surfaces once) when jobs > 1 and there is more than one pose."""
    if not poses:
        return
    if jobs <= 1 or len(poses) == 1:
        _prepare_worker(model)
        yield from (_fit_one(p) for p in poses)
        return
    ctx = multiprocessing.get_context("spawn")
    with cf.ProcessPoolExecutor(max_workers=min(jobs, len(poses)), mp_context=ctx, initializer=_prepare_worker,
                                initargs=(model, os.getpid())) as pool:
        with deaf_to_ctrl_c():
            futures = [pool.submit(_fit_one, p) for p in poses]
        yield from (f.result() for f in futures)


_WORKER: dict = {}     # this process's fit state: the model and its part surfaces, joint frames and face parts


def _prepare_worker(model: HandModel, parent: int | None = None) -> None:
    """Build this process's fit state for `model` (in a worker process: also its Ctrl-C and parent handling)."""
    # MeshLab and the proximity queries load only for a fit (the sampler reads fits without them).
    from darthand.model.intersections import face_parts   # MeshLab: only for a fit
    from darthand.model.proximity import PartSurfaces     # the fit's distances: only for a fit

    if parent is not None:
        init_worker(parent)
    digest = model_digest(model)
    if _WORKER.get("digest") != digest:
        _WORKER.update(digest=digest, model=model, surfaces=PartSurfaces(model),
                       frames=joint_frames(model), face_part=face_parts(model))


def _fit_one(pose: LibraryPose) -> tuple[str, dict]:
    """(name, record entry) of one pose fitted to this process's model (_prepare_worker)."""
    from darthand.model.gesture_fit import fit_gesture   # MeshLab: only for a fit

    w = _WORKER
    t0 = time.perf_counter()
    with threadpool_limits(limits=1, user_api="blas"):   # small products: threaded BLAS only spin-waits
        r = fit_gesture(w["model"], w["surfaces"], w["frames"], pose.name, pose.angles, list(pose.contacts),
                        w["face_part"])
    return pose.name, {"joints": angles_to_joints(r.angles), "status": r.status, "changed_deg": r.changed,
                       "max_change_deg": round(max(map(abs, r.changed.values()), default=0.0), 3),
                       "crossing": r.crossing, "seconds": round(time.perf_counter() - t0, 3)}


def earlier_fit(path: str | Path) -> dict | None:
    """The fit record at `path` to take unchanged poses from, or None when there is none or it is unreadable (a
    damaged record is fitted again, not an error)."""
    try:
        return read_fit(path) if Path(path).is_file() else None
    except (InputError, OSError):
        return None


def select_poses(names: list[str] | None) -> list[LibraryPose]:
    """The library poses named `names` (library order), or all of them for None; InputError naming an unknown one."""
    poses = library_poses()
    if names is None:
        return poses
    known = {p.name for p in poses}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise InputError(f"--poses: no library pose {unknown[0]!r} (assets_src/poses/library)")
    return [p for p in poses if p.name in set(names)]


def fitted_poses(model: HandModel, fit: str | Path | None = None,
                 beside: str | Path | None = None) -> list[LibraryPose]:
    """The library poses the fit of `model` found as model_library finds it holds (a fit of part of the library,
    `make assets LIBRARY_POSES=...`, holds some); all of them when there is no fit."""
    _, record = _fit_record(model, fit, beside)
    poses = library_poses()
    return poses if record is None else [p for p in poses if p.name in record["poses"]]


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
