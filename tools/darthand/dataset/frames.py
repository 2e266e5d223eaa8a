"""One dataset frame in a worker: render a job (render.api) with its background, add the dataset's labels (MANO
parameters in the camera frame, the posed mesh, the sampling record, the split) and write its files:

    images/<n>.png   RGBA, opaque over a background
    masks/<n>.png    8-bit coverage of hand and accessory
    labels/<n>.json  schemas/labels.schema.json; 'files' relative to the labels file
    meshes/<n>.npy   (V, 3) float32 posed hand vertices in the camera frame, metres (the model's vertex order;
                     the first labels.mesh.base_vertices are the hand without the wrist rings, MANO's 778 for MANO)
    maps/<kind>/<n>.png  per-pixel truth when the run asks for it (settings 'maps': depth, normals, parts;
                     render/truth.py's encodings, recorded in labels.maps)

A frame of several hands (a job's `bodies`, render/bodies.py) has its labels per hand in labels.hands (with
hand_type and the job's interaction record), meshes/<n>.npy (B, V, 3) (each hand in bodies order), and one more file:

    instances/<n>.png  8-bit: 0 background, 1 + 2b hand b, 2 + 2b hand b's accessory (render/labels.instance_map)

A frame with a held object (a job's `bodies` with an object item, render/objects.py) is such a frame (its object id
3 in the instance map beside one hand, its labels in labels.objects with the job's grasp record) and writes:

    object_meshes/<n>.npy  (N, 3) float32 the object's closed mesh in the camera frame, metres (the catalogue's
                     vertex order; its faces are the catalogue's)

<n> is the frame index zero-padded to MIN_DIGITS digits (more when larger), so names depend on nothing else.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from darthand.dataset.backgrounds import background_pixels
from darthand.dataset.environments import match_background
from darthand.dataset.film import frame_film
from darthand.dataset.jobs import job_hands, job_objects
from darthand.errors import InputError
from darthand.fileio import atomic_path
from darthand.model.shape import shaped_vertices
from darthand.render import truth
from darthand.render.api import shading_options, write_frame
from darthand.render.bodies import is_group, model_pose
from darthand.render.cycles import CyclesRenderer
from darthand.render.environment import backdrop_blur
from darthand.render.dress import geometry_options
from darthand.render.image import write_png
from darthand.render.labels import instance_map, mano_camera_parameters
from darthand.render.scenes import Scene
from darthand.template.anthropometry import hand_sizes

MIN_DIGITS = 6
KINDS = ("image", "mask", "labels", "vertices")      # the files of every frame; truth maps add their kinds
INSTANCES = "instances"
OBJECT_MESHES = "object_meshes"
RING_WEAR = 1             # version of how a ring frame wears its ring (accessories/wear.py), in its digest


def frame_names(index: int, maps: tuple = (), instances: bool = False, objects: bool = False) -> dict:
    """Names (relative to the dataset folder) of frame `index`'s files, by kind; maps: the truth maps' kinds the
    run writes (render/truth.KINDS), each maps/<kind>/<n>.png; instances: a frame of several hands' instance map;
    objects: a frame with a held object's mesh."""
    n = f"{int(index):0{MIN_DIGITS}d}"
    return {"image": f"images/{n}.png", "mask": f"masks/{n}.png", "labels": f"labels/{n}.json",
            "vertices": f"meshes/{n}.npy", **{kind: f"maps/{kind}/{n}.png" for kind in maps},
            **({INSTANCES: f"instances/{n}.png"} if instances else {}),
            **({OBJECT_MESHES: f"object_meshes/{n}.npy"} if objects else {})}


def write_order(maps: tuple = (), instances: bool = False, objects: bool = False) -> tuple:
    """The kinds of a frame's files in the order they are written: the labels last (a frame is whole once its
    labels exist)."""
    return ("vertices", *maps, *((INSTANCES,) if instances else ()), *((OBJECT_MESHES,) if objects else ()),
            "image", "mask", "labels")


def group_job(job: dict) -> bool:
    """Whether a job's frame is one of several hands (its scene drawn by render/bodies.py: labels per hand, an
    instance map)."""
    return is_group(Scene.from_job(job))


def object_job(job: dict) -> bool:
    """Whether a job's frame holds an object (it writes the object's mesh)."""
    return bool(job_objects(job))


def job_digest(job: dict, settings: dict) -> str:
    """sha256 (hex, 16 digits) of what a frame's files depend on: the job and the render settings (with the
    shading options in full, the renderer's defaults filled in: frames rendered before a default changed are
    rendered again). The truth maps are part of it only when asked (a run without them keeps its digests)."""
    key = {"job": job, **{k: settings[k] for k in ("size", "samples", "aa_shading")},
           "shading": shading_options(settings.get("shading")).to_json()}
    if settings.get("maps"):
        key["maps"] = list(settings["maps"])
    if settings.get("engine"):             # the fast renderer's frames keep their digests
        key["engine"] = settings["engine"]
    if settings.get("film") is not None:
        key["film"] = settings["film"]
    if settings.get("geometry"):
        key["geometry"] = settings["geometry"]          # only when on: digests of runs without it stay
    if wears_ring(job):
        key["ring_wear"] = RING_WEAR       # ring frames rendered before rings were worn per pose are made again
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]


def wears_ring(job: dict) -> bool:
    """Whether the job's accessory is a ring: its sampling record's accessory type, else its id's first word (as
    the planner names a type it cannot look up, plan._accessory_kind)."""
    kind = (job.get("sample") or {}).get("accessory") or str(job.get("accessory") or "").split("_")[0]
    return kind == "ring" or any(str(hand.get("accessory") or "").split("_")[0] == "ring"
                                 for hand in job.get("bodies") or ())


def render_job(renderer, job: dict, settings: dict):
    """(api.Frame, background info or None) of one job, rendered as its scene (render/scenes.py). settings: size,
    samples, aa_shading, and optionally shading (api.shading_options' dict; None: the renderer's defaults), maps
    (render/truth.KINDS to compute), engine ({'name': 'cycles', 'samples': N}: the image from Cycles,
    render/cycles.py), film (dataset/film.film_setting's; None: no film) and geometry (render/dress.GeometryOptions'
    fields; None: off)."""
    scene = Scene.from_job(job)
    if settings.get("engine"):
        renderer = CyclesRenderer(renderer, settings["engine"]["samples"])
    size = settings["size"]
    background, info = None, None
    t = time.perf_counter()
    blur = backdrop_blur(scene.background)
    if blur is not None:
        background = scene.background                 # the environment itself: drawn through the frame's camera
        environment = scene.lights.get("environment", {}) if isinstance(scene.lights, dict) else {}
        info = {"used": f"environment:{Path(str(environment.get('map', '?'))).stem}", "blur": blur, "skipped": []}
    elif isinstance(scene.background, dict):
        background, info = background_pixels(scene.background, size, size)
        if "folder" in scene.background and isinstance(scene.lights, dict) and "environment" in scene.lights:
            scene = replace(scene, lights={**scene.lights, "environment": match_background(     # a photo behind
                scene.lights["environment"], background)})
    t = time.perf_counter() - t
    film, film_seed = frame_film(settings.get("film"), job)
    geometry = geometry_options(settings.get("geometry"))
    frame = renderer.render_scene(scene, background=background, width=size, height=size,
                                  samples=settings["samples"], aa_shading=settings["aa_shading"],
                                  shading=settings.get("shading"), maps=tuple(settings.get("maps") or ()),
                                  film=film, film_seed=film_seed, subdivision=geometry.subdivision, arm=geometry.arm)
    frame.timings["background"] = t
    return frame, info


def dataset_labels(frame, job: dict, digest: str, source, background: dict | None) -> dict:
    """The frame's labels with the dataset's fields added (see the module docstring)."""
    labels = frame.labels
    fields = job_hands(job)[0]            # the hand's job fields: the job itself, or its one body
    maps = tuple(frame.maps)
    names = frame_names(job["index"], maps)
    render = dict(labels.get("render", {}))
    render["dataset"] = {"frame": job["index"], "job_sha256": digest}
    if background is not None:
        render["background"] = background
    labels["render"] = render
    labels["gesture"] = labels.get("gesture") or job.get("gesture")
    model = source.pose_model()
    labels["mesh"] = mesh_record(model, frame.subject.hand_vertices)
    labels["files"] = {**labels.get("files", {}), "vertices": "../" + names["vertices"],
                       **{kind: "../" + names[kind] for kind in maps}}
    if maps:
        labels["maps"] = truth.describe(maps, {kind: "../" + names[kind] for kind in maps})
    if model is not None:
        labels["mano"] = mano_camera_parameters(model, frame.subject.pose, frame.camera.R, frame.camera.t,
                                                fields.get("betas"))
    worn = frame.subject.info.get("ring_worn")
    if worn is not None:
        labels["accessory"] = {**labels["accessory"], "worn": worn}
    labels["split"] = job.get("split", "none")
    labels["sample"] = {**job.get("sample", {}), "side": labels["side"], "skin_tone_offset":
                        fields.get("skin_tone_offset", 0.0), "texture_id": labels["texture"]["id"],
                        "accessory_id": labels["accessory"]["id"]}
    if model is not None:
        labels["sample"]["shape"] = {**labels["sample"].get("shape", {}), **shape_record(model, fields.get("betas"))}
    return labels


def group_dataset_labels(frame, job: dict, digest: str, sources: dict, background: dict | None) -> dict:
    """The labels of a frame of several hands (render/labels.group_labels) with the dataset's fields: as
    `dataset_labels` for the frame, and per hand its mesh record, camera-frame MANO parameters (its placement
    composed with the camera) and its ring's wear; the job's interaction record; the sampling record per hand."""
    labels = frame.labels
    maps = tuple(frame.maps)
    names = frame_names(job["index"], maps, instances=True, objects=bool(frame.subject.objects))
    labels["render"] = {**labels.get("render", {}), "dataset": {"frame": job["index"], "job_sha256": digest},
                        **({"background": background} if background is not None else {})}
    labels["files"] = {**labels.get("files", {}), **{kind: "../" + names[kind] for kind in
                                                     ("vertices", INSTANCES, *maps)},
                       **({OBJECT_MESHES: "../" + names[OBJECT_MESHES]} if frame.subject.objects else {})}
    for entry in labels.get("objects", ()):
        grasp = job.get("grasp") or (job.get("grasps") or [{}])[0]
        entry["grasp"] = {"type": grasp.get("type"), "id": grasp.get("id")}
        if job.get("grasps"):                        # two hands on the object (held, handover): one per hand
            entry["grasps"] = job["grasps"]
    if maps:
        labels["maps"] = truth.describe(maps, {kind: "../" + names[kind] for kind in maps})
    if job.get("interaction") is not None:
        labels["interaction"] = job["interaction"]
    labels["split"] = job.get("split", "none")
    samples = []
    for entry, member, item in zip(labels["hands"], frame.subject.members, job_hands(job)):
        model = sources[member.side].pose_model()
        entry["mesh"] = mesh_record(model, member.hand_vertices)
        if model is not None:
            P = np.asarray(member.info.get("placement", np.eye(4)), np.float64)
            R, t = frame.camera.R @ P[:3, :3], frame.camera.R @ P[:3, 3] + frame.camera.t
            entry["mano"] = mano_camera_parameters(model, model_pose(member), R, t, item.get("betas"))
        if member.info.get("ring_worn") is not None:
            entry["accessory"] = {**entry["accessory"], "worn": member.info["ring_worn"]}
        samples.append({"side": entry["side"], "skin_tone_offset": item.get("skin_tone_offset", 0.0),
                        "texture_id": entry["texture"]["id"], "accessory_id": entry["accessory"]["id"],
                        **({"shape": shape_record(model, item.get("betas"))} if model is not None else {})})
    labels["sample"] = {**job.get("sample", {}), "hands": samples}
    return labels


def mesh_record(model, vertices: np.ndarray) -> dict:
    """labels' mesh record of a hand's posed model vertices (N, 3) (base_vertices: those before the wrist rings)."""
    wrist = (getattr(model, "meta", None) or {}).get("wrist") or {}
    return {"vertices": int(len(vertices)), "base_vertices": int(wrist.get("base_vertices", len(vertices))),
            "faces": "the model's faces (build/model/<side>.npz)", "frame": "camera", "units": "m"}


def shape_record(model, betas) -> dict:
    """The frame's hand shape: betas relative to the source model (as labels.mano), the betas the model was built
    with, their sum (the shape in the model's shape space), and the shaped hand's length and breadth (mm, the
    anthropometric landmarks of template/anthropometry.py)."""
    b = np.zeros(model.num_betas)
    given = np.asarray(betas if betas is not None else [], np.float64)
    b[:len(given)] = given
    baked = np.zeros(model.num_betas)
    built = np.asarray(model.meta.get("betas", []), np.float64)[:model.num_betas]
    baked[:len(built)] = built
    sizes = {k: round(float(v[0]), 2) for k, v in hand_sizes(model, shaped_vertices(model, b)[None]).items()}
    return {"betas": b.round(6).tolist(), "model_betas": baked.round(6).tolist(),
            "absolute_betas": (b + baked).round(6).tolist(), **sizes}


def write_dataset_frame(frame, job: dict, digest: str, out_dir, source, background: dict | None,
                        sources: dict | None = None) -> dict:
    """Write the frame's four files and its truth maps (atomically, in write_order: the labels last, a frame is
    whole once its labels exist); returns its summary for the shard record. sources: {side: source} of a frame of
    several hands (default: `source`'s side only), which also writes its instance map."""
    if frame.subject.members:
        return _write_group_frame(frame, job, digest, out_dir, sources or {source.side: source}, background)
    names = frame_names(job["index"], tuple(frame.maps))
    labels = dataset_labels(frame, job, digest, source, background)
    vertices = frame.camera.to_camera(frame.subject.hand_vertices).astype(np.float32)
    path = Path(out_dir) / names["vertices"]
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.save(f, vertices)
    truth.write_truth_maps(frame.maps, {kind: Path(out_dir) / names[kind] for kind in frame.maps})
    write_frame(frame, out_dir, names={k: names[k] for k in ("image", "mask", "labels")})
    return summary(job, labels)


def _write_group_frame(frame, job: dict, digest: str, out_dir, sources: dict, background: dict | None) -> dict:
    """write_dataset_frame of a frame of several hands: meshes (B, V, 3), the instance map, then as one hand's."""
    objects = frame.subject.objects
    names = frame_names(job["index"], tuple(frame.maps), instances=True, objects=bool(objects))
    labels = group_dataset_labels(frame, job, digest, sources, background)
    counts = {len(m.hand_vertices) for m in frame.subject.members}
    if len(counts) != 1:
        raise InputError(f"meshes: the hands have different vertex counts ({', '.join(map(str, sorted(counts)))})")
    vertices = np.stack([frame.camera.to_camera(m.hand_vertices) for m in frame.subject.members]).astype(np.float32)
    out = Path(out_dir)
    for kind in ("vertices", INSTANCES):
        (out / names[kind]).parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out / names["vertices"]) as tmp, open(tmp, "wb") as f:
        np.save(f, vertices)
    truth.write_truth_maps(frame.maps, {kind: out / names[kind] for kind in frame.maps})
    write_png(out / names[INSTANCES], instance_map(frame.geom, frame.subject), srgb=False)
    if objects:
        write_object_mesh(out / names[OBJECT_MESHES], objects[0], frame.camera)
    write_frame(frame, out_dir, names={k: names[k] for k in ("image", "mask", "labels")})
    return summary(job, labels)


def write_object_mesh(path: Path, held, camera) -> None:
    """object_meshes/<n>.npy: a held object's (render/objects.HeldObject) closed mesh, camera frame, float32."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.save(f, camera.to_camera(held.vertices()).astype(np.float32))


def summary(job: dict, labels: dict) -> dict:
    """A frame's line in its shard record: what the report and the writers need without opening the labels."""
    if "hands" in labels:
        return _group_summary(job, labels)
    bg = labels.get("render", {}).get("background") or {}
    sample = labels.get("sample", {})
    return {"index": job["index"], "side": labels["side"], "split": labels.get("split", "none"),
            "texture": labels["texture"]["id"], "tone": sample.get("texture", {}).get("tone"),
            "category": sample.get("texture", {}).get("category"),
            "skin_tone_offset": labels["texture"]["skin_tone_offset"], "accessory": labels["accessory"]["id"],
            "accessory_type": sample.get("accessory", "none"), "coverage": round(float(labels["coverage"]), 5),
            "visible": [int(v) for v in labels["visibility"]], "in_image": int(sum(labels["in_image"])),
            "background": bg.get("used"), "skipped_backgrounds": bg.get("skipped", [])}


def _group_summary(job: dict, labels: dict) -> dict:
    """`summary` of a frame of several hands: the first hand's fields (side: the frame's hand_type), each hand's
    in 'hands', and the interaction type."""
    first = labels["hands"][0]
    bg = labels.get("render", {}).get("background") or {}
    hands = [{"side": h["side"], "texture": h["texture"]["id"], "accessory": h["accessory"]["id"],
              "coverage": round(float(h["coverage"]), 5), "visible": [int(v) for v in h["visibility"]],
              "in_image": int(sum(h["in_image"]))} for h in labels["hands"]]
    return {"index": job["index"], "side": labels["hand_type"], "split": labels.get("split", "none"),
            "texture": first["texture"]["id"], "tone": None, "category": None,
            "skin_tone_offset": first["texture"]["skin_tone_offset"], "accessory": first["accessory"]["id"],
            "accessory_type": None, "coverage": round(float(labels["coverage"]), 5),
            "visible": hands[0]["visible"], "in_image": hands[0]["in_image"], "background": bg.get("used"),
            "skipped_backgrounds": bg.get("skipped", []), "hands": hands,
            "interaction": (labels.get("interaction") or {}).get("type"),
            **({"objects": [{"id": o["id"], "category": o["category"], "grasp_type": (o.get("grasp") or {}).get("type"),
                             "visible_fraction": round(float(o["visible_fraction"]), 4)}
                            for o in labels["objects"]]} if labels.get("objects") else {})}


def existing_frame(out: Path, job: dict, digest: str, maps: tuple = ()) -> dict | None:
    """The summary of a frame already rendered from this job (all its files present, the truth maps' of `maps`
    too, a frame of several hands' instance map, its labels carrying the job's digest), or None."""
    names = frame_names(job["index"], maps, group_job(job), object_job(job))
    if not all((out / n).is_file() for n in names.values()):
        return None
    try:
        labels = json.loads((out / names["labels"]).read_text())
    except (OSError, ValueError):
        return None
    if labels.get("render", {}).get("dataset", {}).get("job_sha256") != digest:
        return None
    return summary(job, labels)


def frame_error(index: int, error: Exception) -> InputError:
    """The one-line error of a failed frame: 'frame N: cause'."""
    if isinstance(error, InputError):
        return InputError(f"frame {index}: {error}")
    first = (str(error).strip().splitlines() or [""])[0]
    return InputError(f"frame {index}: {type(error).__name__}: {first}")
