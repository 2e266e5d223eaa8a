"""The page's scene (schemas/studio_scene.schema.json) as darthand's own files, and its render.

A scene becomes a one-frame dataset job (schemas/dataset_jobs.schema.json) and renders through the dataset's own
frame path (dataset/frames.render_job), so `darthand render-dataset BUILD/model/<side>.npz --jobs SCENE.json --size N`
renders the exported scene with the same pixels as the studio's Render. Joint angles turn into MANO poses with
model/anatomy.py here, on the server: the page's own conversion (which poses the live view) is checked against it
by the browser tests.
"""

from __future__ import annotations

import base64
import re
import time
from pathlib import Path

import numpy as np

from darthand.dataset.frames import render_job
from darthand.dataset.jobs import check_jobs, validate_jobs
from darthand.dataset.options import DEFAULT_SAMPLES, PHOTO_SHADING
from darthand.errors import InputError
from darthand.fileio import write_json
from darthand.model.anatomy import angles_to_axis_angle
from darthand.model.layout import NUM_JOINTS
from darthand.model.mirror import mirror_pose
from darthand.render.api import Renderer
from darthand.render.camera import Camera
from darthand.render.film import Film
from darthand.render.image import encode_mask8, write_png
from darthand.render.lights import load_lighting
from darthand.schemas import check_schema
from darthand.studio.build import RequestError, StudioBuild

SCENE_SCHEMA = "studio_scene.schema.json"
SAMPLES, AA_SHADING = DEFAULT_SAMPLES, "triangle"   # render-dataset's defaults: the exported jobs render alike
MAX_POSES = 10_000                           # poses in one exported pose list
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")


# ------------------------------------------------------------------------------------------------ checking


def check_scene(build: StudioBuild, scene) -> dict:
    """The scene checked (schema, ids from the build's catalogues, a square camera with a rotation R, lights);
    RequestError 400/404 naming the field otherwise."""
    _checked(lambda: check_schema(scene, SCENE_SCHEMA, "scene"))
    side = build.side(scene["side"])
    if "texture" in scene:
        build.texture(side, scene["texture"])
    if "accessory" in scene:
        build.accessory(side, scene["accessory"])
    camera = scene.get("camera")
    if camera is not None:
        if camera["width"] != camera["height"]:
            raise RequestError(400, f"scene: field 'camera' is {camera['width']}x{camera['height']}: the studio "
                                    "renders square images, as render-dataset does")
        _checked(lambda: Camera(np.asarray(camera["K"]), np.asarray(camera["R"]), np.asarray(camera["t"]),
                                camera["width"], camera["height"]))
    lights = scene.get("lights")
    if lights is not None:
        _checked(lambda: load_lighting(_job_lights(build, lights), "scene: lights"))   # the map by its file
    background = scene.get("background")
    if isinstance(background, dict) and "image" in background:
        build.background_file(background["image"])
    if isinstance(background, dict) and "environment" in background and not (lights or {}).get("environment"):
        raise RequestError(400, "scene: field 'background' is the environment, but the lights have none")
    if scene.get("film") is not None:
        _checked(lambda: Film.from_json(scene["film"], "scene: film"))
    if "object" in scene:
        held_objects(build).grasp(side.side, scene["object"]["id"], scene["object"]["grasp"])
    return scene


def held_objects(build: StudioBuild):
    """The build's studio/objects.StudioObjects (RequestError 404 when the studio has no object catalogue)."""
    if build.objects is None:
        raise RequestError(404, "scene: field 'object': the studio has no object catalogue (--objects-catalog)")
    return build.objects


def _checked(check) -> None:
    try:
        check()
    except RequestError:
        raise
    except InputError as e:
        raise RequestError(400, str(e)) from None


def scene_pose(build: StudioBuild, scene: dict) -> np.ndarray:
    """(48,) MANO axis-angle pose of the scene's hand from its joint angles (degrees)."""
    model = build.side(scene["side"]).model
    angles = np.deg2rad(np.asarray(scene["angles_deg"], np.float64))
    return angles_to_axis_angle(model, angles).reshape(3 * NUM_JOINTS)


def scene_job(build: StudioBuild, scene: dict, index: int = 0) -> dict:
    """The checked scene as a dataset job (schemas/dataset_jobs.schema.json)."""
    job = {"index": index, "side": scene["side"], "pose": [float(x) for x in scene_pose(build, scene)],
           "texture": scene.get("texture"), "skin_tone_offset": float(scene.get("skin_tone_offset", 0.0)),
           "accessory": scene.get("accessory", "none"), "camera": scene.get("camera") or "three_quarter",
           "lights": _job_lights(build, scene.get("lights")),
           "background": _job_background(build, scene.get("background"))}
    job = {k: v for k, v in job.items() if v is not None}
    return job if "object" not in scene else object_job(build, scene, job)


def object_job(build: StudioBuild, scene: dict, job: dict) -> dict:
    """A one-hand job holding the scene's object, as a dataset's object frame is (dataset/objects.object_job): the
    `bodies` form (the hand at the identity, the object at the grasp's refitted placement carried by the scene's
    wrist: StudioObjects.held_placement) with the grasp record."""
    held = held_objects(build)
    object_id, grasp_id = scene["object"]["id"], scene["object"]["grasp"]
    fields = ("side", "pose", "texture", "skin_tone_offset", "accessory")
    hand = {"kind": "hand", **{k: job[k] for k in fields if k in job}}
    placement = np.round(held.held_placement(scene["side"], scene["object"], np.asarray(job["pose"])), 9).tolist()
    out = {k: v for k, v in job.items() if k not in fields}
    return {**out, "bodies": [hand, {"kind": "object", "object": object_id, "placement": placement}],
            "grasp": held.grasp_record(scene["side"], object_id, grasp_id)}


def _job_lights(build: StudioBuild, lights):
    """The lights document with its environment's map id turned into what the renderer reads (a built-in's name,
    a folder map's path); RequestError 404 (an unknown id) or 422 (a map listed unusable)."""
    if not lights or "environment" not in lights:
        return lights
    environment = {**lights["environment"], "map": build.environments.job_map(lights["environment"]["map"])}
    return {**lights, "environment": environment}


def _job_background(build: StudioBuild, background):
    if not background:
        return None
    if "image" in background:
        path = build.background_file(background["image"])
        return {"folder": str(path.parent), "files": [path.name], "builtin": 0}
    if "environment" in background:          # the dataset's form (render/environment.backdrop_blur), blur 0 too
        return {"environment": True, "blur": float(background["environment"].get("blur", 0.0))}
    return dict(background)


# ------------------------------------------------------------------------------------------------ rendering


def render_scene(build: StudioBuild, scene: dict) -> dict:
    """Render the scene as its dataset job would be: {'image', 'mask' (PNG bytes, base64), 'labels', 'job',
    'seconds'}."""
    check_scene(build, scene)
    job = scene_job(build, scene)
    side = build.side(scene["side"])
    size = int(scene["camera"]["width"]) if scene.get("camera") else 512
    # a dataset's skin (dataset/options.py), so that render-dataset --jobs draws the export the same; no arm: the
    # live view shows the package's forearm cap (the export's command says --arm off)
    settings = {"size": size, "samples": SAMPLES, "aa_shading": AA_SHADING, "shading": dict(PHOTO_SHADING)}
    if scene.get("film") is not None:
        settings["film"] = scene["film"]
    t = time.perf_counter()
    with side.lock:
        if side.renderer is None:
            side.renderer = Renderer(side.source, objects=None if build.objects is None else build.objects.library)
        try:
            frame, background = render_job(side.renderer, job, settings)
        except InputError as e:
            raise RequestError(400, f"render: {e}") from None
    labels = frame.labels
    if background is not None:
        labels["render"] = {**labels.get("render", {}), "background": background}
    return {"image": _png64(frame.rgba), "mask": _png64(encode_mask8(frame.alpha), srgb=False), "labels": labels,
            "job": job, "size": size, "seconds": round(time.perf_counter() - t, 3)}


def _png64(pixels: np.ndarray, srgb: bool = True) -> str:
    """Base64 PNG bytes of (H, W[, C]) uint8 pixels (render/image.write_png's encoding)."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "frame.png"
        write_png(path, pixels, srgb=srgb)
        return base64.b64encode(path.read_bytes()).decode()


# ------------------------------------------------------------------------------------------------ exports


def pose_document(pose: np.ndarray) -> dict:
    """A pose file (schemas/pose.schema.json): one or more MANO vectors relative to the flat hand."""
    pose = np.asarray(pose, np.float64)
    vectors = pose.reshape(-1, 3 * NUM_JOINTS).tolist()
    return {"pose": vectors[0] if pose.ndim == 1 else vectors, "flat_hand_mean": True}


def right_hand_poses(build: StudioBuild, angles_deg) -> np.ndarray:
    """(N, 48) right-hand MANO poses of joint angles (N, 16, 3) degrees: the reference poses `render-dataset
    --poses` samples for right hands (and mirrors for left frames). The angles are mirror-symmetric
    (model/anatomy.py), so a pose authored on a left hand gives its right-hand twin."""
    angles = np.deg2rad(np.asarray(angles_deg, np.float64))
    if "right" in build.sides:
        return angles_to_axis_angle(build.sides["right"].model, angles).reshape(-1, 3 * NUM_JOINTS)
    left = angles_to_axis_angle(build.sides["left"].model, angles).reshape(-1, 3 * NUM_JOINTS)
    return mirror_pose(left)


def check_pose_list(doc) -> list:
    """The 'poses' list of an export request: 1..MAX_POSES arrays of 16 x 3 finite angles (degrees)."""
    poses = doc.get("poses") if isinstance(doc, dict) else None
    if not isinstance(poses, list) or not 1 <= len(poses) <= MAX_POSES:
        raise RequestError(400, f"poses: field 'poses' must be a list of 1..{MAX_POSES} joint-angle arrays")
    a = None
    try:
        a = np.asarray(poses, np.float64)
    except (TypeError, ValueError):
        pass
    if a is None or a.shape != (len(poses), NUM_JOINTS, 3) or not np.isfinite(a).all() or np.abs(a).max() > 180:
        raise RequestError(400, "poses: field 'poses' must hold arrays of 16 x 3 finite angles within +-180 degrees")
    return poses


def export_name(doc, default: str) -> str:
    name = doc.get("name", default) if isinstance(doc, dict) else default
    if not isinstance(name, str) or not NAME.match(name):
        raise RequestError(400, f"export: field 'name' {name!r} must match {NAME.pattern}")
    return name


def write_export(build: StudioBuild, kind: str, name: str, doc) -> Path:
    """Write an export atomically as BUILD/studio/<kind>/<name>.json (kind: poses, pose_lists, scenes); returns its
    path. The document is checked against its schema first."""
    schema = {"poses": "pose.schema.json", "pose_lists": "pose.schema.json",
              "scenes": "dataset_jobs.schema.json"}[kind]
    check_schema(doc, schema, f"{kind} export")
    path = build.out_dir / kind / f"{name}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json(path, doc)
    return path


def scene_export(build: StudioBuild, scene: dict, path_hint: str) -> dict:
    """The one-frame jobs file of a scene, with how to render it. A scene holding an object passes
    render-dataset's own checks first (dataset/jobs.validate_jobs: no hand into its object deeper than 1 mm), so
    the file renders in batch; RequestError 422 naming the depth otherwise."""
    job = scene_job(build, scene)
    if "object" in scene:
        try:
            validate_jobs({scene["side"]: build.side(scene["side"]).source}, [job], "scene export",
                          objects=held_objects(build).library)
        except InputError as e:
            raise RequestError(422, str(e)) from None
    size = int(scene["camera"]["width"]) if scene.get("camera") else 512
    model = build.side(scene["side"]).source.source
    objects = f" --objects-catalog {build.objects.objects_file}" if "object" in scene else ""
    studio: dict = {"size": size, "samples": SAMPLES, "aa_shading": AA_SHADING,
                    "command": f"darthand render-dataset {model} --jobs {path_hint} --size {size} --arm off{objects} "
                               "--out OUT",
                    "scene": {k: v for k, v in scene.items() if k != "name"}}
    if scene.get("film") is not None:
        studio["film"] = scene["film"]
    doc = {"frames": [job], "studio": studio}
    check_jobs(doc, "scene export")
    return doc
