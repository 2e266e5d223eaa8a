"""Jobs files: what to render, one job per frame (schemas/dataset_jobs.schema.json): reading, checking against a
source before anything renders, and writing (`render-dataset --plan`, one job per line, streamed).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import atomic_path, read_json
from darthand.model.preview import VIEWS
from darthand.render.lights import load_lighting
from darthand.render.object_contacts import object_contacts
from darthand.render.poses import resolve_pose
from darthand.render.scenes import BODIES, BODY_KINDS, HAND_FIELDS, HandBody, ObjectBody, rigid_error
from darthand.schemas import check_schema

JOBS_SCHEMA = "dataset_jobs.schema.json"
MAX_INDEX = 10**12 - 1                 # frame names have at most 12 digits
# Two hands of a job passing into each other deeper than this (m) are refused: a hand-written placement that puts one
# hand through the other (the plan's own jobs are resolved to no crossing at all, dataset/interactions.py).
PASS_THROUGH_M = 1e-3


def load_jobs(path) -> list[dict]:
    """The jobs of a jobs file (a list of job dicts, or {"frames": [...]}), checked (check_jobs). Relative pose-file,
    lights and background-folder paths in it are taken relative to the file's folder."""
    path = Path(path)
    doc = read_json(path, "dataset jobs file")
    frames = check_jobs(doc, str(path))
    base = path.resolve().parent
    out = []
    for job in frames:
        if BODIES in job:
            job[BODIES] = [_relative_to(dict(item), base, ("pose",)) for item in job[BODIES]]
        _relative_to(job, base, ("pose", "lights"))
        bg = job.get("background")
        if isinstance(bg, dict) and "folder" in bg and not Path(bg["folder"]).is_absolute():
            job["background"] = {**bg, "folder": str(base / bg["folder"])}
        out.append(job)
    return out


def _relative_to(fields: dict, base: Path, keys: tuple) -> dict:
    """`fields` with its relative file paths at `keys` (those naming a file under `base`) made absolute."""
    for key in keys:
        value = fields.get(key)
        if isinstance(value, str) and not Path(value).is_absolute() and (base / value).is_file():
            fields[key] = str(base / value)
    return fields


def write_jobs(path, jobs, plan: dict | None = None) -> int:
    """Write a jobs file {"plan": plan, "frames": [...]} atomically, one job per line, streaming the jobs (an
    iterable); returns how many were written."""
    count = 0
    with atomic_path(path) as tmp, open(tmp, "w") as f:
        f.write('{"plan": ' + json.dumps(plan, sort_keys=True) + ', "frames": [\n' if plan is not None
                else '{"frames": [\n')
        for job in jobs:
            f.write((",\n" if count else "") + json.dumps(job, sort_keys=True))
            count += 1
        f.write("\n]}\n")
    return count


def check_jobs(doc, source: str = "jobs") -> list[dict]:
    """The frames of a jobs document (list or {"frames": [...]}) checked against the schema, with an 'index' each
    (its position when not given); InputError naming the field for a non-finite number, an index over MAX_INDEX or a
    repeated index; a job with both a `bodies` list and one-hand fields, more than two hands or one object, a body of
    an unknown kind or a placement that is not a rigid transform."""
    frames = doc.get("frames") if isinstance(doc, dict) else doc
    prefix = "frames." if isinstance(doc, dict) else ""
    for k, job in enumerate(frames if isinstance(frames, list) else []):
        if isinstance(job, dict) and isinstance(job.get(BODIES), list):
            _check_bodies(job, f"{source}: field '{prefix}{k}")
    check_schema(doc, JOBS_SCHEMA, source)
    frames = doc["frames"] if isinstance(doc, dict) else doc
    out: list = []
    seen: dict = {}
    for k, job in enumerate(frames):
        job = dict(job)
        job.setdefault("index", k)
        where = f"{prefix}{k}"
        _check_finite(job, f"{source}: field '{where}")
        if job["index"] > MAX_INDEX:
            raise InputError(f"{source}: field '{where}.index' {job['index']} is over the largest frame index "
                             f"{MAX_INDEX}")
        if job["index"] in seen:
            raise InputError(f"{source}: field '{where}.index' {job['index']} repeats the index of job "
                             f"{seen[job['index']]}")
        seen[job["index"]] = k
        out.append(job)
    return out


def job_hands(job: dict) -> list[dict]:
    """The hand fields of a job: its `bodies` items of kind 'hand' (a two-hand or object job), or the job itself (a
    one-hand job)."""
    return [b for b in job[BODIES] if b.get("kind") == HandBody.kind] if BODIES in job else [job]


def job_objects(job: dict) -> list[dict]:
    """The `bodies` items of kind 'object' of a job (none for a one-hand job)."""
    return [b for b in job.get(BODIES) or () if b.get("kind") == ObjectBody.kind]


def job_sides(job: dict, default: str) -> list[str]:
    """The sides of a job's hands, each once, in its bodies' order (`default` for a hand without a side)."""
    return list(dict.fromkeys(hand.get("side") or default for hand in job_hands(job)))


def _check_bodies(job: dict, where: str) -> None:
    """InputError (where: "<source>: field '<path>") for a job of both forms, a body of an unknown kind or a
    placement that is not a 4x4 rigid transform (read before the schema: its messages would not name these)."""
    both = [k for k in HAND_FIELDS if k in job]
    if both:
        raise InputError(f"{where}' holds both 'bodies' and the one-hand field {both[0]!r} (a job holds one form)")
    kinds = [item.get("kind") for item in job[BODIES] if isinstance(item, dict)]
    for kind, most in ((HandBody.kind, 2), (ObjectBody.kind, 1)):
        if kinds.count(kind) > most:
            raise InputError(f"{where}.bodies' holds {kinds.count(kind)} bodies of kind {kind!r} (at most {most})")
    for b, item in enumerate(job[BODIES]):
        if not isinstance(item, dict):
            continue
        if item.get("kind") not in BODY_KINDS:
            raise InputError(f"{where}.bodies.{b}.kind' {item.get('kind')!r} is not a body kind (known: "
                             f"{', '.join(BODY_KINDS)})")
        if item.get("placement") is not None:
            why = rigid_error(item["placement"])
            if why:
                raise InputError(f"{where}.bodies.{b}.placement' {why}")


def _check_finite(value, where: str) -> None:
    """InputError for NaN or Infinity anywhere in a job (JSON readers accept them; they render black frames and
    write labels that are not JSON)."""
    if isinstance(value, float) and not math.isfinite(value):
        raise InputError(f"{where}' is {value}, not a finite number")
    if isinstance(value, dict):
        for k, v in value.items():
            _check_finite(v, f"{where}.{k}")
    elif isinstance(value, list):
        for k, v in enumerate(value):
            _check_finite(v, f"{where}.{k}")


def validate_jobs(sources: dict, jobs: list[dict], where: str = "jobs", objects=None) -> None:
    """InputError (naming the frame and field) for what the sources ({side: source}) cannot render: a side without a
    source, unknown texture, accessory or gesture ids, poses a USD package cannot take, bad camera, lights or
    background documents, an object not in the object catalogue `objects` (render/objects.ObjectLibrary; None: no
    catalogue) or a hand passing into its object. Runs before any rendering."""
    checked_lights: set = set()
    checked_folders: set = set()
    known = {}
    for side, source in sources.items():
        model, gestures = source.pose_model(), set(source.gesture_names())
        known[side] = (set(source.texture_ids()), set(source.accessory_ids()) | {"none"}, gestures, model)
    default_side = next(iter(sources))
    for job in jobs:
        at = f"{where}: frame {job['index']}"
        for b, hand in enumerate(job_hands(job)):
            _check_hand(hand, known, default_side, at + (f": bodies.{b}" if BODIES in job else ""))
        _check_scene(job, at, checked_lights, checked_folders)
        if len(job_hands(job)) == 2:
            _check_hands_apart(job_hands(job), known, default_side, at)
        for item in job_objects(job):
            _check_object(item, job_hands(job), objects, known, default_side, at)


def _check_hand(job: dict, known: dict, default_side: str, at: str) -> None:
    """validate_jobs' checks of one hand's fields (a one-hand job, or a bodies item) against its side's source."""
    side = job.get("side") or default_side
    if side not in known:
        raise InputError(f"{at}: side {side!r} has no source (sides: {', '.join(known)})")
    textures, accessories, gestures, model = known[side]
    texture, accessory, pose = job.get("texture"), job.get("accessory"), job.get("pose")
    if texture is not None and texture not in textures:
        raise InputError(f"{at}: texture {texture!r} is not in the source's textures")
    if accessory is not None and accessory not in accessories:
        raise InputError(f"{at}: accessory {accessory!r} is not in the source's accessories")
    if isinstance(pose, str) and pose not in gestures and (model is None or not Path(pose).is_file()):
        raise InputError(f"{at}: pose {pose!r} is not a gesture ({', '.join(sorted(gestures))})"
                         + (" nor a pose file" if model is not None else " of the package"))
    if job.get("betas") is not None:
        if model is None:
            raise InputError(f"{at}: betas: a USD package renders its baked shape")
        if len(job["betas"]) > model.num_betas:
            raise InputError(f"{at}: betas: {len(job['betas'])} given but the model has {model.num_betas} "
                             "shape directions")
    if model is None and isinstance(pose, list):
        raise InputError(f"{at}: pose: a USD package renders its gestures (names or time codes), not vectors")
    if model is not None and isinstance(pose, int) and not isinstance(pose, bool):
        raise InputError(f"{at}: pose: a time code needs a USD package")


def _check_hands_apart(hands: list[dict], known: dict, default_side: str, at: str) -> None:
    """InputError when a job's two hands, posed by their sides' models and placed, pass into each other deeper than
    PASS_THROUGH_M (model/hand_pair: vertices inside the other hand; MeshLab's crossing faces counted in the
    message). Hands of a USD package (no model to pose) are not measured."""
    # Imported here: the pair geometry loads MeshLab, which only jobs files of two hands need.
    from darthand.model.hand_pair import penetration

    posed = [_posed_hand(hand, known, default_side) for hand in hands]
    if any(p is None for p in posed):
        return
    found = penetration(*posed)
    if found.max_m > PASS_THROUGH_M:
        raise InputError(f"{at}: the two hands pass through each other ({1000 * found.max_m:.1f} mm deep, "
                         f"{found.crossing_faces} faces crossing): move the left hand's placement")


def _check_object(item: dict, hands: list[dict], objects, known: dict, default_side: str, at: str) -> None:
    """InputError when a job's object is not in the catalogue `objects` (render/objects.ObjectLibrary, None: no
    catalogue) or a hand, posed by its side's model, passes into it deeper than PASS_THROUGH_M (hands of a USD
    package are not measured)."""
    if objects is None:
        raise InputError(f"{at}: object {item['object']!r} needs an object catalogue (--objects-catalog)")
    if item["object"] not in objects.items:
        raise InputError(f"{at}: object {item['object']!r} is not in the object catalogue")
    placement = np.eye(4) if item.get("placement") is None else np.asarray(item["placement"], np.float64)
    for hand in hands:
        posed = _posed_hand(hand, known, default_side)
        if posed is None:
            continue
        depth = object_contacts(posed.vertices, objects.item(item["object"]), placement).penetration_max_m
        if depth > PASS_THROUGH_M:
            raise InputError(f"{at}: the {hand.get('side') or default_side} hand passes into object "
                             f"{item['object']!r} ({1000 * depth:.1f} mm deep): move the object's placement")


def _posed_hand(hand: dict, known: dict, default_side: str):
    """A job's hand item posed by its side's model and placed (model/hand_pair.PosedHand), None for a hand of a USD
    package (no model to pose)."""
    # Imported here: the pair geometry loads MeshLab, which only jobs of several bodies need.
    from darthand.model.hand_pair import pose_hand

    model = known[hand.get("side") or default_side][3]
    if model is None:
        return None
    pose, _ = resolve_pose(model, hand.get("pose"), int(hand.get("pose_index") or 0))
    placement = hand.get("placement")
    return pose_hand(model, pose, hand.get("betas"), None if placement is None else np.asarray(placement, np.float64))


def _check_scene(job: dict, at: str, checked_lights: set, checked_folders: set) -> None:
    """validate_jobs' checks of a job's camera, lights and background (each lights document and folder once)."""
    camera = job.get("camera")
    if isinstance(camera, dict):
        check_schema(camera, "camera.schema.json", f"{at}: camera")
    elif isinstance(camera, str) and camera not in VIEWS and not Path(camera).is_file():
        raise InputError(f"{at}: camera {camera!r} is neither a view ({', '.join(VIEWS)}) nor a camera file")
    lights = job.get("lights")
    key = json.dumps(lights, sort_keys=True)
    if lights is not None and key not in checked_lights:
        lighting = load_lighting(lights, f"{at}: lights")
        _check_finite(lighting.to_json(), f"{at}: field 'lights")
        checked_lights.add(key)
    background = job.get("background")
    if isinstance(background, dict) and "folder" in background and background["folder"] not in checked_folders:
        if not Path(background["folder"]).is_dir():
            raise InputError(f"{at}: background folder {background['folder']!r} is not a folder")
        checked_folders.add(background["folder"])
