"""Labelled datasets: many frames planned from a seed (`plan_frames`) or read from a jobs file (`load_jobs`), rendered
frame-parallel over worker processes (`render_dataset`) into

    OUT/images/000000.png   RGBA (straight alpha; opaque over a background)
    OUT/masks/000000.png    8-bit coverage of hand and accessory
    OUT/labels/000000.json  labels (schemas/labels.schema.json); 'files' relative to the labels file
    OUT/dataset.json        the run: package, where the jobs came from, per-frame summary, timings

A job is a plain JSON dict (schemas/dataset_jobs.schema.json): pose (gesture name, 48 MANO axis-angle numbers
relative to the flat hand, pose file path, or a USD time code), texture id, skin_tone_offset, accessory id or 'none',
camera spec (camera.load_camera: a view name or {"view": [x, y, z], "roll_deg", "margin", ...} framed on the posed
hand) and lights (a lights document or None for the default rig). Frame i's job depends only on (seed, i), so
sharding, resuming or `start` never change a frame.

Why the frames are grouped by texture: decoding a 2048^2 skin texture and building its mip pyramid costs 0.1 to
0.2 s, three to five 512^2 frames (render/texture.py caches 512 MB of pyramids; a skin-tone offset is only a decode
table on a cached pyramid, about 0.5 ms). So the frames are handed to the workers in chunks of one texture, sorted
by accessory inside (an accessory change costs 5-17 ms).

Workers are started with 'spawn' (a fresh interpreter: nothing inherited from a parent that may hold an Embree
device or thread pools); each opens the source once and renders single-threaded. Frames go back to the parent only
as small summaries.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import read_json, write_bytes, write_json

DATASET_FORMAT = "darthand-dataset"
DATASET_VERSION = 1
JOBS_SCHEMA = "dataset_jobs.schema.json"
MIN_DIGITS = 6
MAX_CHUNK = 32                    # frames per task: ~2 s of work, so progress and Ctrl-C stay responsive
DEFAULT_JITTER_DEG = 5.0          # std of the per-joint, per-axis pose perturbation for a model source
DEFAULT_ROLL_RANGE = (-30.0, 30.0)
DEFAULT_MARGIN_RANGE = (0.03, 0.15)
# Random views avoid a cone about +X (the forearm's direction, from which the camera would look along the arm at
# the wrist's cut end): cos of the angle to +X at most this (about 37 degrees).
WRIST_CONE_COS = 0.8
RANDOM_VIEW = "random"
# Which of a frame's uniforms (frame_draws) decides what.
POSE, TEXTURE, TONE, BARE, ACCESSORY, VIEW, DIRECTION, ROLL, MARGIN = 0, 1, 2, 3, 4, 5, 6, 8, 9   # DIRECTION: 6, 7
_DRAWS = 10


# ------------------------------------------------------------------------------------------------ planning


def plan_frames(source, count: int, *, seed: int = 0, start: int = 0, poses=None, textures=None,
                accessories=None, views=None, skin_tone_range=(-0.1, 0.1), skin_tone_steps: int | None = None,
                no_accessory_share: float = 0.3, pose_jitter_deg: float | None = None,
                roll_range_deg=DEFAULT_ROLL_RANGE, margin_range=DEFAULT_MARGIN_RANGE, lights=None) -> list[dict]:
    """Jobs of frames start .. start + count - 1 of a random dataset of `source` (an opened api.open_source).

    Frame i draws from numpy's Generator seeded with [seed, i], a fixed number of values in a fixed order, so its
    job depends only on (seed, i) and these options.

    poses: gesture names and/or pose files (schemas/pose.schema.json, every pose in it); None: every gesture of the
        source. pose_jitter_deg: standard deviation (degrees) of a Gaussian added to each finger joint's twist,
        spread and bend angle (model/anatomy.py), clipped to the joint limits (widened to the unperturbed angle when
        that lies outside them); None: DEFAULT_JITTER_DEG for a model source, 0 for a USD package (which renders its
        baked gestures only). A perturbed pose is written as 48 numbers, its gesture kept in 'gesture'.
    textures: texture ids (None: every catalogue texture; 'plain' without a catalogue; never the UV 'checker').
    skin_tone_range, skin_tone_steps: the sRGB offset is uniform in the range (rounded to 1e-4), or one of
        `skin_tone_steps` evenly spaced levels of it (1: its middle).
    accessories: accessory ids (None: all); a share `no_accessory_share` of the frames gets 'none'.
    views: 'random' (or None) and/or named views (camera.VIEWS), one chosen per frame. A random view is a direction
        uniform on the sphere outside the forearm cone (WRIST_CONE_COS). Every view gets a roll uniform in
        roll_range_deg and a free border `margin` uniform in margin_range, and is framed on the posed hand.
    lights: a lights document (dict) or file, the same for every frame; None: the renderer's default rig.
    """
    count, start, seed = _count(count, "count"), _count(start, "start"), _count(seed, "seed")
    pool = pose_pool(source, poses, pose_jitter_deg)
    tex = _pick_ids("textures", textures, _default_textures(source), source.texture_ids())
    acc = _pick_ids("accessories", accessories, [a for a in source.accessory_ids() if a != "none"],
                    source.accessory_ids(), allow_empty=True)
    acc = [a for a in acc if a != "none"]
    tones = skin_tones(skin_tone_range, skin_tone_steps)
    view_pool = _views(views)
    if not 0 <= no_accessory_share <= 1:
        raise InputError(f"no_accessory_share: {no_accessory_share} is outside 0..1")
    roll, margin = _range("roll_range_deg", roll_range_deg), _range("margin_range", margin_range, 0.0, 0.45)
    light_doc = _lights_doc(lights)

    draws = [frame_draws(seed, start + k) for k in range(count)]
    which = [int(_choose(u[POSE], len(pool.entries))) for u, _ in draws]
    poses = pool.poses(which, np.array([z for _, z in draws]).reshape(count, 15, 3))
    jobs = []
    for k, (u, _) in enumerate(draws):
        name = view_pool[_choose(u[VIEW], len(view_pool))]
        jobs.append({
            "index": start + k,
            "pose": poses[k], "gesture": pool.entries[which[k]]["gesture"],
            "texture": tex[_choose(u[TEXTURE], len(tex))],
            "skin_tone_offset": (tones[_choose(u[TONE], len(tones))] if skin_tone_steps else
                                 round(float(tones[0] + (tones[-1] - tones[0]) * u[TONE]), 4)),
            "accessory": "none" if not acc or u[BARE] < no_accessory_share else acc[_choose(u[ACCESSORY], len(acc))],
            "camera": {"view": random_view(u[DIRECTION], u[DIRECTION + 1]) if name == RANDOM_VIEW else name,
                       "roll_deg": round(float(roll[0] + (roll[1] - roll[0]) * u[ROLL]), 2),
                       "margin": round(float(margin[0] + (margin[1] - margin[0]) * u[MARGIN]), 4)},
            "lights": light_doc})
    return jobs


def frame_draws(seed: int, index: int) -> tuple[np.ndarray, np.ndarray]:
    """Frame `index`'s random numbers: (_DRAWS,) uniforms in [0, 1) (the choices, by the indices POSE ... MARGIN)
    and (15, 3) standard normals (the finger joints' pose jitter), from numpy's Generator seeded with [seed, index].
    All are drawn whatever the options, in this order, so that one option never shifts another's draws."""
    rng = np.random.default_rng([seed, index])
    return rng.random(_DRAWS), rng.standard_normal((15, 3))


class PosePool:
    """The poses a plan draws from: entries {'gesture': name or None, 'pose': gesture name or (48,) list,
    'angles': (16, 3) anatomical angles in radians or None}, and how to perturb them."""

    def __init__(self, entries: list[dict], jitter_rad: float = 0.0, model=None):
        self.entries, self.jitter, self.model = entries, jitter_rad, model

    def poses(self, which: list[int], noise: np.ndarray) -> list:
        """Per frame the pose of entry which[k], perturbed by jitter * noise[k] (15, 3) (finger joints)."""
        if not self.jitter:
            return [self.entries[w]["pose"] for w in which]
        from darthand.model.anatomy import angles_to_axis_angle, joint_frames, limits_radians

        base = np.stack([self.entries[w]["angles"] for w in which]) if len(which) else np.zeros((0, 16, 3))
        lim = limits_radians()[1:]
        lo, hi = np.minimum(lim[..., 0], base[:, 1:]), np.maximum(lim[..., 1], base[:, 1:])
        angles = base.copy()
        angles[:, 1:] = np.clip(base[:, 1:] + self.jitter * noise, lo, hi)
        pose = angles_to_axis_angle(self.model, angles, joint_frames(self.model)).reshape(len(which), -1)
        return [p.tolist() for p in pose]


def pose_pool(source, poses=None, jitter_deg: float | None = None) -> PosePool:
    """The PosePool of gesture names and pose files `poses` (None: every gesture the source knows)."""
    model = getattr(source, "model", None)
    if model is None:                                   # a USD package: its gestures, as baked
        if jitter_deg:
            raise InputError("pose jitter: a USD package renders its baked gestures only (use 0, or a model)")
        names = list(source.gestures) if poses is None else list(poses)
        for name in names:
            if name not in source.gestures:
                raise InputError(f"poses: {name!r} is not a gesture of the package ({', '.join(source.gestures)})")
        if not names:
            raise InputError("poses: the package has no gestures")
        return PosePool([{"gesture": n, "pose": n, "angles": None} for n in names])

    from darthand.model.anatomy import axis_angle_to_angles
    from darthand.model.gestures import model_gestures
    from darthand.render.poses import pose_file_vectors

    jitter = DEFAULT_JITTER_DEG if jitter_deg is None else float(jitter_deg)
    if not 0 <= jitter <= 45:
        raise InputError(f"pose jitter: {jitter} degrees is outside 0..45")
    entries, gestures = [], model_gestures(model)
    for item in (gestures.names if poses is None else list(poses)):
        item = str(item)
        if item in gestures.names:
            entries.append({"gesture": item, "pose": item, "angles": gestures.angles_of(item)})
            continue
        if not Path(item).is_file():
            raise InputError(f"poses: {item!r} is neither a gesture ({', '.join(gestures.names)}) nor a pose file")
        vectors = pose_file_vectors(model, item)
        angles = axis_angle_to_angles(model, vectors)
        entries += [{"gesture": None, "pose": v.tolist(), "angles": a} for v, a in zip(vectors, angles)]
    if not entries:
        raise InputError("poses: no gesture or pose given")
    return PosePool(entries, np.deg2rad(jitter), model)


def skin_tones(value_range=(-0.1, 0.1), steps: int | None = None) -> list[float]:
    """The skin-tone offsets a plan draws from: `steps` levels evenly spaced over the range (1: its middle); None:
    the range's ends (the offset is drawn uniformly between them)."""
    lo, hi = _range("skin_tone_range", value_range, -0.5, 0.5)
    if steps is None:
        return [round(float(lo), 6), round(float(hi), 6)]
    if int(steps) < 1:
        raise InputError(f"skin_tone_steps: {steps} must be at least 1")
    levels = [0.5 * (lo + hi)] if int(steps) == 1 else np.linspace(lo, hi, int(steps)).tolist()
    return [round(float(x), 6) for x in levels]


def random_view(u: float, v: float) -> list[float]:
    """A unit direction from the hand toward the camera for two uniforms in [0, 1): uniform on the part of the sphere
    whose x is at most WRIST_CONE_COS (on a sphere, x uniform in [-1, c] and the angle about the x axis uniform give
    a uniform density over that zone, Archimedes' hat-box theorem)."""
    x = -1.0 + (1.0 + WRIST_CONE_COS) * float(u)
    r, phi = math.sqrt(max(0.0, 1.0 - x * x)), 2 * math.pi * float(v)
    return [round(x, 6), round(r * math.cos(phi), 6), round(r * math.sin(phi), 6)]


def _choose(u, n: int):
    """Index in 0..n-1 of uniform(s) u in [0, 1)."""
    return np.minimum((np.asarray(u) * n).astype(np.int64), n - 1)


def _default_textures(source) -> list[str]:
    """Every texture of the catalogue (or USD variant set), not the UV checker; 'plain' only when there is none."""
    ids = [t for t in source.texture_ids() if t != "checker"]
    return [t for t in ids if t != "plain"] or ids


def _pick_ids(what: str, wanted, default: list[str], known: list[str], allow_empty: bool = False) -> list[str]:
    if wanted is None or wanted == "all":
        ids = list(default)
    else:
        ids = [wanted] if isinstance(wanted, str) else list(wanted)
        for i in ids:
            if i not in known:
                shown = ", ".join(known[:6]) + (" ..." if len(known) > 6 else "")
                raise InputError(f"{what}: {i!r} is not one of the source's ids ({shown})")
    if not ids and not allow_empty:
        raise InputError(f"{what}: no ids to choose from")
    return ids


def _views(views) -> list[str]:
    from darthand.model.preview import VIEWS

    names = [RANDOM_VIEW] if views is None else ([views] if isinstance(views, str) else list(views))
    for name in names:
        if name != RANDOM_VIEW and name not in VIEWS:
            raise InputError(f"views: {name!r} is not '{RANDOM_VIEW}' or a view ({', '.join(VIEWS)})")
    if not names:
        raise InputError("views: no view given")
    return names


def _range(what: str, value, lo: float = -math.inf, hi: float = math.inf) -> tuple[float, float]:
    try:
        a, b = (float(x) for x in value)
    except (TypeError, ValueError):
        raise InputError(f"{what}: {value!r} is not a pair of numbers") from None
    if not (lo <= a <= b <= hi):
        raise InputError(f"{what}: ({a}, {b}) must be ordered and within {lo}..{hi}")
    return a, b


def _count(value, what: str) -> int:
    if isinstance(value, bool) or int(value) != value or int(value) < 0:
        raise InputError(f"{what}: {value!r} must be a non-negative integer")
    return int(value)


def _lights_doc(lights):
    """A lights document (checked) from a dict or a file, or None."""
    if lights is None:
        return None
    from darthand.render.lights import load_lighting

    doc = read_json(lights, "lights file") if isinstance(lights, (str, Path)) else lights
    load_lighting(doc, str(lights) if isinstance(lights, (str, Path)) else "lights")
    return doc


# ------------------------------------------------------------------------------------------------ jobs files


def load_jobs(path) -> list[dict]:
    """The jobs of a jobs file (a list of job dicts, or {"frames": [...]}; schemas/dataset_jobs.schema.json).
    Relative pose-file and lights paths in it are taken relative to the file's folder."""
    path = Path(path)
    doc = read_json(path, "dataset jobs file")
    frames = check_jobs(doc, str(path))
    base = path.resolve().parent
    out = []
    for job in frames:
        job = dict(job)
        for key in ("pose", "lights"):
            value = job.get(key)
            if isinstance(value, str) and not Path(value).is_absolute() and (base / value).is_file():
                job[key] = str(base / value)
        out.append(job)
    return out


def write_jobs(path, jobs: list[dict], plan: dict | None = None) -> None:
    """Write a jobs file {"plan": plan, "frames": jobs} (atomically), one job per line."""
    head = json.dumps({"plan": plan}, sort_keys=True)[:-1] if plan is not None else "{"
    lines = ",\n".join(json.dumps(job, sort_keys=True) for job in jobs)
    write_bytes(path, f'{head}{", " if plan is not None else ""}"frames": [\n{lines}\n]}}\n'.encode())


def check_jobs(doc, source: str = "jobs") -> list[dict]:
    """The frames of a jobs document (list or {"frames": [...]}) checked against the schema, with an 'index' each
    (its position when not given); InputError naming the field, or a repeated index."""
    from darthand.schemas import check_schema

    check_schema(doc, JOBS_SCHEMA, source)
    frames = doc["frames"] if isinstance(doc, dict) else doc
    out, seen = [], {}
    for k, job in enumerate(frames):
        job = dict(job)
        job.setdefault("index", k)
        if job["index"] in seen:
            field = f"frames.{k}.index" if isinstance(doc, dict) else f"{k}.index"
            raise InputError(f"{source}: field '{field}' {job['index']} repeats the index of job {seen[job['index']]}")
        seen[job["index"]] = k
        out.append(job)
    return out


def validate_jobs(source, jobs: list[dict], where: str = "jobs") -> None:
    """InputError (naming the frame and field) for what the source cannot render: unknown texture, accessory or
    gesture ids, poses a USD package cannot take, bad camera or lights documents. Runs before any rendering."""
    from darthand.render.lights import load_lighting
    from darthand.model.preview import VIEWS
    from darthand.schemas import check_schema

    textures, accessories = set(source.texture_ids()), set(source.accessory_ids()) | {"none"}
    model = getattr(source, "model", None)
    if model is not None:
        from darthand.model.gestures import model_gestures

        gestures = set(model_gestures(model).names)
    else:
        gestures = set(source.gestures)
    lights_seen = set()
    for job in jobs:
        at = f"{where}: frame {job['index']}"
        texture, accessory, pose = job.get("texture"), job.get("accessory"), job.get("pose")
        if texture is not None and texture not in textures:
            raise InputError(f"{at}: texture {texture!r} is not in the source's textures")
        if accessory is not None and accessory not in accessories:
            raise InputError(f"{at}: accessory {accessory!r} is not in the source's accessories")
        if isinstance(pose, str) and pose not in gestures and (model is None or not Path(pose).is_file()):
            raise InputError(f"{at}: pose {pose!r} is not a gesture ({', '.join(sorted(gestures))})"
                             + (" nor a pose file" if model is not None else " of the package"))
        if model is None and isinstance(pose, list):
            raise InputError(f"{at}: pose: a USD package renders its gestures (names or time codes), not vectors")
        if model is not None and isinstance(pose, int) and not isinstance(pose, bool):
            raise InputError(f"{at}: pose: a time code needs a USD package")
        camera = job.get("camera")
        if isinstance(camera, dict):
            check_schema(camera, "camera.schema.json", f"{at}: camera")
        elif isinstance(camera, str) and camera not in VIEWS and not Path(camera).is_file():
            raise InputError(f"{at}: camera {camera!r} is neither a view ({', '.join(VIEWS)}) nor a camera file")
        lights = job.get("lights")
        key = json.dumps(lights, sort_keys=True)
        if lights is not None and key not in lights_seen:
            load_lighting(lights, f"{at}: lights")
            lights_seen.add(key)


# ------------------------------------------------------------------------------------------------ rendering


def render_dataset(package, out_dir, jobs, *, processes: int | None = None, size: int = 512, samples: int = 8,
                   aa_shading: str = "triangle", background=None, textures=None, accessories=None, model=None,
                   resume: bool = True, progress=True, threads: int | None = None, chunk_size: int | None = None,
                   source=None, jobs_source: dict | None = None) -> dict:
    """Render `jobs` (a list of job dicts, or a jobs file) of PACKAGE (api.open_source, with the catalogue paths
    textures/accessories and `model`) into out_dir (see the module docstring); returns the dataset.json document.

    processes: worker processes (default: the cores available); 1 renders in this process. threads: render
        threads per process (default 1 with workers, all cores with processes=1).
    resume: skip frames whose image, mask and labels exist and whose labels carry this frame's job digest (the
        job, size, samples, aa_shading and background), so a changed plan re-renders the frames it changed.
    samples, aa_shading: edge anti-aliasing (api.Renderer.render).
    progress: False, True (a line on stdout at most every 5 s) or a callable(done, total, seconds), called as
        chunks finish.
    source: PACKAGE already opened (used to check the jobs, and for processes=1); jobs_source: how the jobs were
        made (seed, options), recorded in dataset.json.
    A frame that fails stops the run with an InputError 'frame N: cause'; files are written atomically, so an
    interrupted run leaves only whole frames and resumes where it stopped.
    """
    from darthand.render import aa

    t_start = time.monotonic()
    if isinstance(jobs, (str, Path)):
        jobs_source = jobs_source or {"file": str(jobs)}
        jobs = load_jobs(jobs)
    else:
        jobs = check_jobs(list(jobs))
    aa.check_options(samples, aa_shading)
    if int(size) < 8:
        raise InputError(f"size: {size} pixels is too small (at least 8)")
    if background is not None:
        background = Path(background).resolve()
        if not background.is_file():
            raise InputError(f"{background}: no such background image")
        background = str(background)
    if source is None:
        from darthand.render.api import open_source

        source = open_source(package, textures=textures, accessories=accessories, model=model)
    validate_jobs(source, jobs)

    out = Path(out_dir)
    settings = {"out_dir": str(out), "size": int(size), "samples": int(samples), "aa_shading": aa_shading,
                "background": background}
    digests = {j["index"]: job_digest(j, settings) for j in jobs}
    done = existing_frames(out, jobs, digests, settings) if resume else {}
    todo = [j for j in jobs if j["index"] not in done]
    processes = max(1, int(processes or len(os.sched_getaffinity(0))))
    chunks = make_chunks(todo, processes, chunk_size)
    processes = min(processes, max(1, len(chunks)))
    report = _progress_printer() if progress is True else (progress or None)
    items = [[(j["index"], j, digests[j["index"]]) for j in chunk] for chunk in chunks]
    if processes == 1:
        results = _run_here(source, items, settings, threads, report, t_start)
    else:
        results = _run_pool((str(package), textures, accessories, model), items, settings, processes,
                            1 if threads is None else threads, report, t_start)
    return _write_dataset(out, package, jobs, jobs_source, done, results, settings, processes, t_start)


def job_digest(job: dict, settings: dict) -> str:
    """sha256 (hex, 16 digits) of what a frame's pixels and labels depend on: the job, size, samples (and their
    shading), background."""
    key = {"job": job, "size": settings["size"], "samples": settings["samples"],
           "aa_shading": settings["aa_shading"], "background": settings["background"]}
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]


def frame_names(index: int) -> dict:
    """write_frame names of frame `index`: images/, masks/, labels/ and the index zero-padded to MIN_DIGITS digits
    (more when it is larger), so a frame's names depend on nothing else."""
    n = f"{index:0{MIN_DIGITS}d}"
    return {"image": f"images/{n}.png", "mask": f"masks/{n}.png", "labels": f"labels/{n}.json"}


def existing_frames(out: Path, jobs: list[dict], digests: dict, settings: dict) -> dict:
    """{index: summary} of the frames already rendered for these jobs: all three files present, the labels carry
    the job's digest."""
    found = {}
    for job in jobs:
        names = frame_names(job["index"])
        if not all((out / n).is_file() for n in names.values()):
            continue
        try:
            labels = json.loads((out / names["labels"]).read_text())
        except (OSError, ValueError):
            continue
        if labels.get("render", {}).get("dataset", {}).get("job_sha256") == digests[job["index"]]:
            found[job["index"]] = _summary(job, labels)
    return found


def make_chunks(jobs: list[dict], processes: int, chunk_size: int | None = None) -> list[list[dict]]:
    """The jobs in tasks for the workers: grouped by texture so that a worker decodes a texture once for many
    frames, each group split into chunks of at most `chunk_size` frames (default: a quarter of an even
    share per process, at most MAX_CHUNK), frames sorted by accessory inside a chunk; largest chunks first (the
    small ones then even out the workers' finishing times)."""
    if not jobs:
        return []
    size = chunk_size or min(MAX_CHUNK, max(1, math.ceil(len(jobs) / (4 * processes))))
    groups: dict = {}
    for job in jobs:
        groups.setdefault(str(job.get("texture")), []).append(job)
    chunks = []
    for key in sorted(groups):
        group = sorted(groups[key], key=lambda j: (str(j.get("accessory")), j["index"]))
        chunks += [group[k:k + size] for k in range(0, len(group), size)]
    return sorted(chunks, key=len, reverse=True)


# The worker's state: set by _init_worker (spawned processes) or _run_here, the source opened on first use.
_STATE: dict = {}


def _init_worker(source_args: tuple, settings: dict, threads: int, stop) -> None:
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)      # the parent handles Ctrl-C and stops the workers
    _STATE.clear()
    _STATE.update(source_args=source_args, settings=settings, threads=threads, stop=stop)


def _render_chunk(items: list) -> dict:
    """Render and write one chunk [(index, job, digest)] with this process's renderer; its frames' summaries."""
    from darthand.render.api import Renderer, open_source, write_frame

    if "renderer" not in _STATE:
        t = time.monotonic()
        package, textures, accessories, model = _STATE["source_args"]
        source = open_source(package, textures=textures, accessories=accessories, model=model)
        _STATE["renderer"] = Renderer(source, _STATE["threads"])
        _STATE["ready"] = time.monotonic()
        _STATE["open_s"] = _STATE["ready"] - t
    renderer, settings, stop = _STATE["renderer"], _STATE["settings"], _STATE.get("stop")
    frames = []
    t0 = time.monotonic()
    for index, job, digest in items:
        if stop is not None and stop.is_set():
            break
        t, c = time.monotonic(), time.process_time()
        try:
            frame = render_job(renderer, job, settings)
            frame.labels["render"] = {**frame.labels.get("render", {}), "dataset": {
                "frame": index, "job_sha256": digest, "gesture": job.get("gesture")}}
            write_frame(frame, settings["out_dir"], names=frame_names(index))
        except InputError as e:
            raise InputError(f"frame {index}: {e}") from None
        except Exception as e:            # a bug or a broken file: still one line naming the frame
            first = (str(e).strip().splitlines() or [""])[0]
            raise InputError(f"frame {index}: {type(e).__name__}: {first}") from None
        end = time.monotonic()
        frames.append({**_summary(job, frame.labels), "ms": round(1000 * (end - t), 2),
                       "cpu_ms": round(1000 * (time.process_time() - c), 2), "end": end})
    return {"pid": os.getpid(), "ready": _STATE["ready"], "open_s": _STATE["open_s"], "start": t0,
            "end": time.monotonic(), "frames": frames}


def render_job(renderer, job: dict, settings: dict):
    """The api.Frame of one job."""
    pose = job.get("pose")
    if isinstance(pose, list):
        pose = np.asarray(pose, np.float64)
    elif isinstance(pose, str) and "pose_index" in job and hasattr(renderer.source, "model"):
        from darthand.render.poses import resolve_pose

        pose = resolve_pose(renderer.source.model, pose, int(job["pose_index"]))[0]
    return renderer.render(pose, texture=job.get("texture"), skin_tone_offset=float(job.get("skin_tone_offset", 0)),
                           accessory=job.get("accessory"), camera=job.get("camera") or "three_quarter",
                           lights=job.get("lights"), background=settings["background"], width=settings["size"],
                           height=settings["size"], samples=settings["samples"],
                           aa_shading=settings["aa_shading"])


def _summary(job: dict, labels: dict) -> dict:
    return {"index": job["index"], "gesture": job.get("gesture"), "texture": labels.get("texture", {}).get("id"),
            "accessory": labels.get("accessory", {}).get("id"), "coverage": round(float(labels["coverage"]), 5),
            "visible_keypoints": int(sum(labels["visibility"])),
            "keypoints_in_image": int(sum(labels["in_image"]))}


def _run_here(source, items, settings, threads, report, t_start) -> list[dict]:
    """processes=1: the chunks in this process, in order."""
    from darthand.render.api import Renderer

    t = time.monotonic()
    _STATE.clear()
    _STATE.update(renderer=Renderer(source, threads), settings=settings, ready=t, open_s=0.0)
    results, done, total = [], 0, sum(len(i) for i in items)
    try:
        for chunk in items:
            results.append(_render_chunk(chunk))
            done += len(chunk)
            if report:
                report(done, total, time.monotonic() - t_start)
    finally:
        _STATE.clear()
    return results


def _run_pool(source_args, items, settings, processes, threads, report, t_start) -> list[dict]:
    """The chunks on `processes` spawned workers, handed out as they free up. The first failed frame (or Ctrl-C)
    stops the workers after their current frame and is raised."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    ctx = multiprocessing.get_context("spawn")
    stop = ctx.Event()
    results, done, total = [], 0, sum(len(i) for i in items)
    pool = ProcessPoolExecutor(processes, mp_context=ctx, initializer=_init_worker,
                               initargs=(source_args, settings, threads, stop))
    futures = {pool.submit(_render_chunk, chunk): chunk for chunk in items}
    pending = set(futures)
    try:
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for f in finished:
                try:
                    result = f.result()
                except BrokenProcessPool:
                    raise InputError(f"frame {futures[f][0][0]}: a worker process died (killed, out of memory, "
                                     "or it could not start: see the messages above)") from None
                results.append(result)
                done += len(result["frames"])
            if report:
                report(done, total, time.monotonic() - t_start)
    except BaseException:
        stop.set()
        for f in pending:
            f.cancel()
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    return results


def _progress_printer(every_s: float = 5.0):
    """A progress callback printing a line at most every `every_s` seconds, and at the end."""
    last = [-math.inf]

    def report(done: int, total: int, seconds: float) -> None:
        if done == total or seconds - last[0] >= every_s:
            last[0] = seconds
            print(f"[render-dataset] {done}/{total} frames, {seconds:.1f} s", flush=True)
    return report


def _write_dataset(out: Path, package, jobs, jobs_source, done, results, settings, processes, t_start) -> dict:
    """dataset.json: the run's inputs, per-frame summaries (index order) and timings."""
    t_end = time.monotonic()
    frames = {i: s for i, s in done.items()}
    for r in results:
        for f in r["frames"]:
            frames[f["index"]] = {k: v for k, v in f.items() if k not in ("end", "cpu_ms")}
    doc = {"format": DATASET_FORMAT, "version": DATASET_VERSION, "package": str(package),
           "jobs": jobs_source or {"given": "list"}, "count": len(jobs),
           "size": settings["size"], "samples": settings["samples"], "aa_shading": settings["aa_shading"],
           "background": settings["background"],
           "files": {kind: name.replace("000000", "<index>") for kind, name in frame_names(0).items()},
           "rendered": sum(len(r["frames"]) for r in results), "skipped": len(done),
           "timings": timings(results, processes, t_start, t_end),
           "frames": [frames[j["index"]] for j in jobs if j["index"] in frames]}
    write_json(out / "dataset.json", doc, indent=None)
    return doc


def timings(results: list[dict], processes: int, t_start: float, t_end: float) -> dict:
    """Throughput of a run from the workers' chunk results (monotonic clock times, which the processes share):

    startup_s      from the call until every worker had finished its first frame: spawning, imports, opening the
                   source and the first frame's one-off work (its texture decoded, caches filled)
    open_s         the longest a worker took to open the source
    ms_per_image   steady state: wall time after start-up per frame finished after it (1000 / images_per_second)
    cpu_ms_per_image  CPU time of the rendering processes (all their threads) per frame, after start-up
    frame_ms_median   one frame's render + write time in its worker
    tail_idle_s    how long the first worker to finish waited for the last (the sharding's imbalance)
    """
    frames = [(r["pid"], f) for r in results for f in r["frames"]]
    n = len(frames)
    out = {"processes": processes, "wall_s": round(t_end - t_start, 3), "frames": n}
    if not n:
        return out
    first_end, last_end = {}, {}
    for pid, f in frames:
        first_end[pid] = min(first_end.get(pid, math.inf), f["end"])
        last_end[pid] = max(last_end.get(pid, -math.inf), f["end"])
    warm = max(first_end.values())
    steady_frames = [f for _, f in frames if f["end"] > warm]
    after = len(steady_frames)
    steady = 1000 * (max(last_end.values()) - warm) / after if after else 1000 * (t_end - t_start) / n
    out.update({
        "startup_s": round(warm - t_start, 3),
        "open_s": round(max(r["open_s"] for r in results), 3),
        "ms_per_image": round(steady, 2),
        "images_per_second": round(1000 / steady, 2),
        "overall_images_per_second": round(n / (t_end - t_start), 2),
        "cpu_ms_per_image": round(float(np.mean([f["cpu_ms"] for f in steady_frames or [f for _, f in frames]])),
                                  2),
        "frame_ms_median": round(float(np.median([f["ms"] for _, f in frames])), 2),
        "tail_idle_s": round(max(last_end.values()) - min(last_end.values()), 3),
    })
    return out
