"""Dataset plans: what frame i renders, as a job (schemas/dataset_jobs.schema.json), from (seed, i) and the plan's
options alone, computed on demand (`Planner.job`, `Planner.jobs(start, stop)`), so a plan of 10^9 frames costs no
memory and any shard of it can be planned anywhere.

A plan's options are one JSON document (`plan_spec`), recorded in dataset.json and in written jobs files. Per frame:

- pose: DART's grid-and-slerp sampler ('dart', the default for a model), reference poses with jitter ('jitter'),
  or as they are ('gestures', the only mode of a USD package, which renders its baked gestures) (dataset/poses.py);
  the mirror image for a left hand;
- shape: betas drawn per frame (dataset/shapes.py; default N(0, I) truncated at |beta| <= 3), the same betas for
  either side (a left model's shape directions are the right's mirrored); none for a USD package;
- appearance: texture uniform over the catalogue, skin-tone offset uniform in [-0.15, 0.15] (DART's range) or one
  of `skin_tone_steps` levels, an accessory on `accessory_share` (25 %, DART's rate) of the frames, uniform over the
  catalogue, the hand's side uniform over `sides`;
- view: dataset/views.py (equal-area cells, roll, field of view, size or distance);
- lights: an environment map (dataset/environments.py: a map of the built-in set or a folder, turned, scaled and
  tinted per frame), a random rig (dataset/lighting.py), the renderer's default rig, or one lights document for all
  frames;
- background: dataset/backgrounds.py (built-in set, a folder, or none), or the frame's environment seen through its
  camera ('environment');
- split: train/val/test by `split` fractions, drawn per pose group (the frames of one slerp path share a split, so
  near-identical poses never straddle train and test);
- two hands: on `two_hands` of the frames (default none), the user's right and left hand in an interaction type
  drawn by `interactions` shares (dataset/interactions.py), as a job of two `bodies` (the right hand at the world's
  identity, the left with its placement; both wearing the frame's shape, texture and tone; the accessory on the hand
  of the frame's side draw) with the `interaction` record. Whether a frame has two hands is drawn on its own stream
  (TWO_HANDS_STREAM), so one-hand frames draw as they would without the option; with `two_hands` 0 the plan document
  leaves both options out and every job is as before. The types `held` and `handover` (asked for by name) put both
  hands on one object of the catalogues (dataset/object_pairs.py): the job's bodies add the object at its placement
  and the `grasps` record (one per hand);
- an object held: on `objects` of the frames (default none), the frame's hand holding an object of the catalogue
  (uniform over it, or over `object_categories`) in one of that object's grasps for the frame's side, refitted to
  the frame's shape (dataset/objects.py: drawn on OBJECT_STREAM, redrawn on RETRY_STREAM), as a job of two `bodies`
  (the hand at the identity with the grasp's pose, the object at its placement) with the `grasp` record. A frame is
  a one-hand, a two-hand or an object frame: the object draw comes first (its share of all frames is `objects`),
  and the two-hand draw is then taken under two_hands / (1 - objects) (its share of all frames stays `two_hands`;
  the two shares may sum to at most 1). With `objects` 0 the plan document leaves both options out and every job
  is as before.

Frame i's choices use numpy's Generator seeded with [seed, FRAME_STREAM, i] (a fixed number of uniforms, each with
a fixed role, so that one option never shifts another's draws); poses, views, shapes and the environment have
their own streams.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field, fields, is_dataclass

import numpy as np

from darthand.dataset import backgrounds, environments, interaction_shares, lighting, poses, shapes, views
from darthand.dataset.shapes import ShapeOptions
from darthand.errors import InputError
from darthand.fileio import read_json
from darthand.model.mirror import mirror_model, mirror_pose
from darthand.render.lights import load_lighting

PLAN_VERSION = 2
FRAME_STREAM = 0
SPLIT_STREAM = 4
ENVIRONMENT_STREAM = 6
TWO_HANDS_STREAM = 8                         # 2 uniforms: two hands or one, the interaction type
SPLITS = ("train", "val", "test")
# Which of a frame's uniforms decides what.
TEXTURE, TONE, BARE, ACCESSORY, SIDE = 0, 1, 2, 3, 4
VIEW = 5                                     # 6 uniforms
LIGHTS = VIEW + 6                            # lighting.UNIFORMS
BACKGROUND = LIGHTS + lighting.UNIFORMS      # backgrounds.UNIFORMS
UNIFORMS = BACKGROUND + backgrounds.UNIFORMS



@dataclass
class PoseOptions:
    """How poses are drawn (dataset/poses.py): mode 'auto' (dart for a model, the baked gestures for a USD package),
    'dart', 'jitter' or 'gestures'; reference 'gestures', 'library' (the pose library; 'library:TAG,...' a tagged
    part of it), a pose file or FreiHAND's training_mano.json; gestures: the reference restricted to these names;
    levels, draws, steps: DART's grid and slerp; jitter_deg: std of the jitter (degrees); max_reference_mb: the
    largest reference file read."""

    mode: str = "auto"
    reference: str = "library"
    gestures: list | None = None
    levels: int = poses.DEFAULT_LEVELS
    draws: int = poses.DEFAULT_DRAWS
    steps: int = poses.DEFAULT_STEPS
    jitter_deg: float = poses.DEFAULT_JITTER_DEG
    max_reference_mb: float = poses.DEFAULT_MAX_REFERENCE_MB


@dataclass
class PlanOptions:
    """A plan's options, with their defaults (the module docstring says what each draws): the one place they are
    defined. `spec()` is the plan document recorded in dataset.json and jobs files. Ranges are (lo, hi); textures
    and accessories: ids to draw from (None: every one of the catalogue; accessories [] for none); lights 'environment',
    'random', 'default' or a lights document or file; environments (the maps 'environment' lights draw from)
    'builtin', a folder or a map; backgrounds 'builtin', 'none', 'environment' (the frame's environment behind the
    hand), a folder or an image; split the train/val/test fractions; two_hands the share of frames with two hands
    (0: none, and the plan document leaves it and interactions out); interactions {type: share} (None: equal);
    interaction_fit what the two hands' fit moves: 'digits' (the left hand and the digits near the other hand) or
    'rigid' (the left hand only); objects the share of frames with an object held (0: none, and the plan document
    leaves it and object_categories out), object_categories the catalogue's categories drawn from (None: all; also
    by the held and handover interactions)."""

    seed: int = 0
    poses: PoseOptions = field(default_factory=PoseOptions)
    textures: list | None = None
    skin_tone_range: tuple = (-0.15, 0.15)
    skin_tone_steps: int | None = None
    accessories: list | None = None
    accessory_share: float = 0.25
    sides: tuple = ("right", "left")
    views: tuple = ("random",)
    roll_range_deg: tuple = (-45.0, 45.0)
    fov_range_deg: tuple = (30.0, 60.0)
    margin_range: tuple = (0.03, 0.15)
    distance_range: tuple | None = None
    lights: str | dict = "environment"
    environments: str = "builtin"
    backgrounds: str = "environment"
    split: tuple = (0.8, 0.1, 0.1)
    shapes: ShapeOptions = field(default_factory=ShapeOptions)
    two_hands: float = 0.0
    interactions: dict | str | None = None
    interaction_fit: str = interaction_shares.FITS[0]
    objects: float = 0.0
    object_categories: list | None = None

    def spec(self) -> dict:
        """The plan document (plain JSON values: lists for tuples)."""
        return plan_spec(**{f.name: _plain(getattr(self, f.name)) for f in fields(self)})


def _plain(value):
    """A dataclass as a dict, tuples as lists, recursively (the plan document's JSON form)."""
    if is_dataclass(value):
        return {f.name: _plain(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


# Options in the plan document only when two hands are asked for, so that every plan without them is as before.
TWO_HAND_OPTIONS = ("two_hands", "interactions", "interaction_fit")
OBJECT_OPTIONS = ("objects", "object_categories")            # likewise, only when objects are asked for
DEFAULTS: dict = {k: v for k, v in _plain(PlanOptions()).items() if k not in TWO_HAND_OPTIONS + OBJECT_OPTIONS}


def plan_spec(**options) -> dict:
    """DEFAULTS updated with `options` (None leaves a default; 'poses' merges), checked for unknown names."""
    spec = copy.deepcopy(DEFAULTS)
    for key, value in options.items():
        if key not in spec and key not in TWO_HAND_OPTIONS + OBJECT_OPTIONS:
            raise InputError(f"plan: unknown option {key!r} (known: "
                             f"{', '.join(list(spec) + list(TWO_HAND_OPTIONS + OBJECT_OPTIONS))})")
        if key in ("poses", "shapes"):
            if isinstance(value, str):                  # a shape distribution given by its name
                value = {"mode": value}
            for k, v in (value or {}).items():
                if k not in spec[key]:
                    raise InputError(f"plan: unknown {key[:-1]} option {k!r} (known: {', '.join(spec[key])})")
                if v is not None:
                    spec[key][k] = v
        elif value is not None:
            spec[key] = list(value) if isinstance(value, tuple) else value
    return _object_options(_two_hand_options(spec))


def _object_options(spec: dict) -> dict:
    """The spec with objects checked (a share in 0..1, at most 1 with two_hands) and object_categories a list of
    names or None; both left out when objects is 0 (object_categories kept for two-hand frames on an object, the
    held and handover interactions, when those are asked for)."""
    share = spec.get("objects", 0.0)
    if isinstance(share, bool) or not isinstance(share, (int, float)) or not (math.isfinite(share) and 0 <= share <= 1):
        raise InputError(f"objects: {share!r} is not a share within 0..1")
    if share + spec.get("two_hands", 0.0) > 1 + 1e-12:
        raise InputError(f"objects: {share:g} of the frames with objects and {spec['two_hands']:g} with two hands "
                         "sum to more than all of them")
    categories = spec.get("object_categories")
    if share == 0:
        out = {k: v for k, v in spec.items() if k not in OBJECT_OPTIONS}
        if categories is not None and interaction_shares.object_share(spec.get("interactions") or {}):
            out["object_categories"] = _categories(categories)
        return out
    return {**spec, "objects": float(share), "object_categories": _categories(categories)}


def _categories(categories):
    """object_categories checked: a list of names, or None."""
    if categories is not None and (isinstance(categories, str) or not all(isinstance(c, str) for c in categories)):
        raise InputError(f"object categories: {categories!r} is not a list of category names")
    return None if categories is None else list(categories)


def _two_hand_options(spec: dict) -> dict:
    """The spec with two_hands checked (a share in 0..1) and interactions as checked shares; both left out when
    two_hands is 0."""
    share = spec.get("two_hands", 0.0)
    if isinstance(share, bool) or not isinstance(share, (int, float)) or not (math.isfinite(share) and 0 <= share <= 1):
        raise InputError(f"two hands: {share!r} is not a share within 0..1")
    shares = interaction_shares.parse_shares(spec.get("interactions"))
    fit = spec.get("interaction_fit", interaction_shares.FITS[0])
    if fit not in interaction_shares.FITS:
        raise InputError(f"interaction fit: {fit!r} is not one of {', '.join(interaction_shares.FITS)}")
    if share == 0:
        return {k: v for k, v in spec.items() if k not in TWO_HAND_OPTIONS}
    return {**spec, "two_hands": float(share), "interactions": shares, "interaction_fit": fit}


def split_of(unit: int, seed: int, fractions) -> str:
    """'train', 'val' or 'test' of a split unit (a pose group) from the cumulative fractions."""
    u = np.random.default_rng([seed, SPLIT_STREAM, int(unit)]).random()
    edges = np.cumsum(fractions)
    for name, edge in zip(SPLITS, edges):
        if u < edge:
            return name
    return SPLITS[-1] if edges[-1] >= 1 - 1e-12 else "none"


def check_split(value) -> list[float]:
    """Three fractions >= 0 summing to at most 1 (frames left over belong to no split)."""
    try:
        parts = [float(x) for x in value]
    except (TypeError, ValueError):
        raise InputError(f"split: {value!r} is not three numbers train,val,test") from None
    if len(parts) != 3 or not all(math.isfinite(x) and x >= 0 for x in parts):
        raise InputError(f"split: {value!r} must be three non-negative numbers train,val,test")
    if sum(parts) > 1 + 1e-9:
        raise InputError(f"split: {','.join(f'{x:g}' for x in parts)} sums to {sum(parts):g}, more than 1")
    return parts


def texture_tags(texture_id: str) -> dict:
    """{'tone', 'category'} of a catalogue texture id ('<tone>_<category>_<nn>', base variations 'base_...'; the
    textures stage's naming); 'other' for ids that do not follow it."""
    parts = str(texture_id).split("_")
    if len(parts) >= 3 and parts[-1].isdigit():
        return {"tone": parts[0], "category": "_".join(parts[1:-1])}
    return {"tone": "other", "category": str(texture_id)}


class Planner:
    """The jobs of a plan (`plan_spec`) for its sources ({side: opened source}, dataset/sources.py)."""

    def __init__(self, spec: dict, sources: dict, catalogs: dict | None = None):
        """catalogs: {'objects': path, 'grasps': path}, the catalogues an object frame draws from (read only when
        the plan's `objects` share is not 0)."""
        self.spec = spec = plan_spec(**spec)
        self.seed = _non_negative(spec["seed"], "seed")
        self.sides = [s for s in spec["sides"] if s in sources]
        if not self.sides:
            raise InputError("sides: no source for the sides asked")
        first = sources[self.sides[0]]
        self.textures = _pick_ids("textures", spec["textures"], _default_textures(first), first.texture_ids())
        known_acc = first.accessory_ids()
        acc = _pick_ids("accessories", spec["accessories"], [a for a in known_acc if a != "none"], known_acc,
                        allow_empty=True)
        self.accessories = [a for a in acc if a != "none"]
        self.accessory_kinds = {a: _accessory_kind(first, a) for a in self.accessories}
        share = float(spec["accessory_share"])
        if not (math.isfinite(share) and 0 <= share <= 1):
            raise InputError(f"accessory share: {spec['accessory_share']} is outside 0..1")
        self.accessory_share = share
        self.tones = views.check_range("skin-tone range", spec["skin_tone_range"], -0.5, 0.5)
        steps = spec["skin_tone_steps"]
        if steps is not None and not (isinstance(steps, int) and 1 <= steps <= 1000):
            raise InputError(f"skin-tone steps: {steps} must be an integer within 1..1000")
        self.tone_levels = None if steps is None else (
            [0.5 * sum(self.tones)] if steps == 1 else np.linspace(*self.tones, steps).tolist())
        self.views = views.ViewSampler(spec["views"], roll_deg=spec["roll_range_deg"], fov_deg=spec["fov_range_deg"],
                                       margin=spec["margin_range"], distance=spec["distance_range"])
        self.lights = _lights_mode(spec["lights"])
        self.environments = environments.EnvironmentSet(spec["environments"]) if self.lights == "environment" else None
        self.backdrop = spec["backgrounds"] == "environment"
        if self.backdrop and self.environments is None:
            raise InputError("backgrounds 'environment' shows the frame's environment: it needs lights 'environment'")
        self.backgrounds = backgrounds.BackgroundSampler("none" if self.backdrop else spec["backgrounds"])
        self.split = check_split(spec["split"])
        self.model = _right_model(sources)
        self.hand_centre = _hand_centre(self.model)
        self.poses = _pose_sampler(spec["poses"], self.model, first)
        self.group_size = self.poses.steps if isinstance(self.poses, poses.GridSlerp) else 1
        self.shapes = _shape_sampler(spec["shapes"], self.model)
        spec["shapes"] = self.shapes.spec()
        self.two_hands = spec.get("two_hands", 0.0)
        self.pairs = _interaction_sampler(spec, sources, self.model, catalogs or {}) if self.two_hands else None
        self.objects = spec.get("objects", 0.0)
        self.object_frames = _object_frames(spec, sources, catalogs or {}, self.pairs) if self.objects else None
        self.object_redraws = 0             # refits that failed and were drawn again (this planner's jobs)

    def describe(self) -> dict:
        """What the plan draws from (for dataset.json and the report)."""
        out = {"textures": len(self.textures), "accessories": len(self.accessories), "sides": self.sides,
               "backgrounds": {"kind": "environment"} if self.backdrop else self.backgrounds.describe(),
               "group_size": self.group_size}
        if self.environments is not None:
            out["environments"] = self.environments.describe()
        reference = getattr(self.poses, "reference", None)
        if reference is not None:
            out["reference"] = {"source": reference.source, "poses": len(reference)}
        return out

    def jobs(self, start: int, stop: int):
        """Jobs of frames start .. stop - 1, one at a time."""
        for i in range(int(start), int(stop)):
            yield self.job(i)

    def job(self, index: int) -> dict:
        """The job of frame `index` (a plain JSON dict)."""
        i = _non_negative(index, "frame index")
        u = np.random.default_rng([self.seed, FRAME_STREAM, i]).random(UNIFORMS)
        side = self.sides[_choose(u[SIDE], len(self.sides))]
        pose, pose_record = self.poses.sample(self.seed, i)
        sampled = pose                                       # the right hand's pose (a two-hand frame's too)
        gesture = pose if isinstance(pose, str) else pose_record["reference"].get("name") \
            if pose_record["mode"] == "jitter" else None
        if not isinstance(pose, str):
            if side == "left":
                pose = mirror_pose(pose)
            pose = np.asarray(pose, np.float64).tolist()
        texture = self.textures[_choose(u[TEXTURE], len(self.textures))]
        if self.tone_levels is None:
            tone = round(float(self.tones[0] + (self.tones[1] - self.tones[0]) * u[TONE]), 4)
        else:
            tone = round(float(self.tone_levels[_choose(u[TONE], len(self.tone_levels))]), 6)
        accessory = "none"
        if self.accessories and u[BARE] < self.accessory_share:
            accessory = self.accessories[_choose(u[ACCESSORY], len(self.accessories))]
        camera, view_record = self.views.sample(self.seed, i, u[VIEW:VIEW + 6])
        lights, lights_record = self._lights(u[LIGHTS:LIGHTS + lighting.UNIFORMS], side)
        background = self.backgrounds.sample(u[BACKGROUND:BACKGROUND + backgrounds.UNIFORMS])
        if self.environments is not None:
            u_env = np.random.default_rng([self.seed, ENVIRONMENT_STREAM, i]).random(environments.UNIFORMS)
            environment, lights_record = self.environments.sample(u_env)
            lights = {"environment": environment}
            if self.backdrop:
                background = self.environments.backdrop(u_env)
        betas = self.shapes.sample(self.seed, i)
        sample = {"pose": pose_record, "view": view_record, "lights": lights_record,
                  "texture": texture_tags(texture),
                  "accessory": self.accessory_kinds.get(accessory, "none"),
                  "shape": {"distribution": self.shapes.mode if betas is not None else "none"}}
        job = {"index": i, "side": side, "pose": pose, "gesture": gesture, "texture": texture,
               "skin_tone_offset": tone, "accessory": accessory, "camera": camera, "lights": lights,
               "background": background, "split": split_of(i // self.group_size, self.seed, self.split),
               "sample": sample}
        if betas is not None:
            job["betas"] = betas
        if self.object_frames is not None and self.object_frames.holds(self.seed, i, self.objects):
            draw = self.object_frames.draw(self.seed, i, side, betas)
            if draw is not None:
                self.object_redraws += draw.redraws
                return self.object_frames.job(job, draw)
            job["sample"]["object"] = {"failed": True}            # every redraw failed: a one-hand frame
        elif self.pairs is not None:
            u2 = np.random.default_rng([self.seed, TWO_HANDS_STREAM, i]).random(2)
            if u2[0] < self.two_hands / (1.0 - self.objects):
                return self._two_hand_job(job, u2[1], sampled)
        return job

    def _two_hand_job(self, job: dict, u: float, pose) -> dict:
        """A one-hand job made the frame's two-hand job (pose: the frame's sampled right-hand pose): the `bodies` form
        and its interaction record."""
        assert self.pairs is not None
        i = job["index"]
        pair = self.pairs.sample(self.seed, i, u, np.asarray(pose, np.float64), job.get("betas"), job["accessory"],
                                 job["side"])
        worn, left_off = _worn_on_object(job) if "object" in pair else (job["accessory"], None)
        bodies = []
        for side, key in (("right", "right_pose"), ("left", "left_pose")):
            body = {"kind": "hand", "side": side, "pose": np.asarray(pair[key], np.float64).tolist(),
                    "texture": job["texture"], "skin_tone_offset": job["skin_tone_offset"],
                    "accessory": worn if side == job["side"] else "none"}
            if "betas" in job:
                body["betas"] = job["betas"]
            if side == "left":
                body["placement"] = np.round(pair["placement"], 9).tolist()
            bodies.append(body)
        out = {k: v for k, v in job.items() if k not in ("side", "pose", "texture", "skin_tone_offset",
                                                          "accessory", "betas")}
        if pair["type"] not in ("apart", "overlapping", "mirrored"):
            out["gesture"] = None                       # a type's pre-shape, not the sampled pose
        if "object" in pair:                            # held, handover: the object both hands are on
            held = pair["object"]
            bodies.append({"kind": "object", "object": held["id"],
                           "placement": np.round(held["placement"], 9).tolist()})
            out["grasps"] = pair["grasps"]
        record = pair["record"]
        if left_off:                                    # recorded as a one-hand object frame records it
            out["sample"] = {**job["sample"], "accessory": "none"}
            record = {**record, "object": {**record["object"], "accessory_left_off": left_off}}
        return {**out, "bodies": bodies, "interaction": record}

    def _lights(self, u, side: str):
        if self.lights == "random":
            centre = self.hand_centre * (np.array([-1.0, 1, 1]) if side == "left" else 1)
            return lighting.random_rig(u, centre.tolist())
        if self.lights == "default":
            return None, {"rig": "default"}
        return self.lights, {"rig": "given"}


# ------------------------------------------------------------------------------------------------ helpers


def _pose_sampler(opts: dict, model, first):
    mode = opts["mode"]
    if mode not in ("auto", "dart", "jitter", "gestures"):
        raise InputError(f"pose mode: {mode!r} is not auto, dart, jitter or gestures")
    if model is None:                                       # a USD package: its gestures, as baked
        if mode not in ("auto", "gestures"):
            raise InputError(f"pose mode {mode!r}: a USD package renders its baked gestures only (use a model)")
        known = first.gesture_names()
        names = known if not opts["gestures"] else list(opts["gestures"])
        for name in names:
            if name not in known:
                raise InputError(f"poses: {name!r} is not a gesture of the package ({', '.join(known)})")
        return poses.GestureNames(names)
    reference = poses.load_reference(opts["reference"], model, float(opts["max_reference_mb"]),
                                     gestures=opts["gestures"], model_path=first.describe().get("source"))
    if mode in ("auto", "dart"):
        return poses.GridSlerp(model, reference, levels=opts["levels"], draws=opts["draws"], steps=opts["steps"])
    return poses.GestureJitter(model, reference, 0.0 if mode == "gestures" else opts["jitter_deg"])


def _interaction_sampler(spec: dict, sources: dict, model, catalogs: dict):
    """The two-hand sampler (dataset/interactions.InteractionSampler) on the models both sides' sources pose, with
    the draws of two hands on an object (dataset/object_pairs.py) when the shares ask for them."""
    # Imported here: the pair geometry (MeshLab, the fit) loads only for plans with two hands.
    from darthand.dataset import interactions

    if model is None:
        raise InputError("two hands: a USD package renders baked gestures; two-hand frames need a model")
    if set(sources) != {"right", "left"}:
        raise InputError("two hands: the plan needs both sides' sources (--sides right,left)")
    right, left = sources["right"].pose_model() or model, sources["left"].pose_model()
    held = None
    if interaction_shares.object_share(spec["interactions"]):
        from darthand.dataset.object_pairs import ObjectPairs      # as interactions: only plans that ask load it

        if not catalogs.get("objects") or not catalogs.get("grasps"):
            raise InputError("interactions held/handover: the plan needs the object and grasp catalogues "
                             "(--objects-catalog, --grasps-catalog)")
        held = ObjectPairs(catalogs["objects"], catalogs["grasps"], right, left, spec.get("object_categories"))
    return interactions.InteractionSampler(right, left, spec["interactions"], sources,
                                           fit_digits=spec["interaction_fit"] == "digits", objects=held)


def _object_frames(spec: dict, sources: dict, catalogs: dict, pairs=None):
    """The object-frame sampler (dataset/objects.ObjectFrames) on the models of the plan's sides' sources: the one
    the held/handover draws of `pairs` (the plan's InteractionSampler, or None) built when it is on the same models
    in the same order (the catalogues, their distance fields and its description are then the same), else its own."""
    # Imported here: the grasp refit (the fit's least squares, the objects' distance fields) loads only for plans
    # with objects.
    from darthand.dataset.objects import ObjectFrames

    models = {side: source.pose_model() for side, source in sources.items() if side in spec["sides"]}
    if any(model is None for model in models.values()):
        raise InputError("objects: a USD package renders baked gestures; object frames need a model")
    if not catalogs.get("objects") or not catalogs.get("grasps"):
        raise InputError("objects: the plan needs the object and grasp catalogues (--objects-catalog, "
                         "--grasps-catalog)")
    held = None if pairs is None or pairs.objects is None else pairs.objects.frames
    if held is not None and _same_models(held.models, models):
        return held
    return ObjectFrames(catalogs["objects"], catalogs["grasps"], models, spec.get("object_categories"))


def _same_models(a: dict, b: dict) -> bool:
    """Whether two {side: HandModel} are the same sides in the same order, each the same model object."""
    return list(a) == list(b) and all(a[side] is b[side] for side in a)


def _shape_sampler(opts: dict, model) -> shapes.ShapeSampler:
    """The plan's shape sampler; a USD package (no model) renders its baked shape only."""
    if model is None:
        if opts.get("mode") != "none" and opts != shapes.DEFAULTS:
            raise InputError("shapes: a USD package renders its baked shape (use a model, or --shapes none)")
        return shapes.ShapeSampler({"mode": "none"}, 0)
    return shapes.ShapeSampler(opts, model.num_betas)


def _right_model(sources: dict):
    """The right-handed model poses are planned on (a left source's model mirrored); None for USD packages."""
    for source in sources.values():
        model = source.pose_model()
        if model is None:
            return None
        if model.side == "right":
            return model

    return mirror_model(next(iter(sources.values())).pose_model())


def _hand_centre(model) -> np.ndarray:
    if model is None:
        return np.zeros(3)
    v = np.asarray(model.v_template)
    return 0.5 * (v.min(0) + v.max(0))


def _lights_mode(value):
    if value in ("environment", "random", "default", None):
        return value or "default"
    doc = read_json(value, "lights file") if isinstance(value, str) else value
    load_lighting(doc, str(value) if isinstance(value, str) else "lights")
    return doc


def _worn_on_object(job: dict) -> tuple[str, str | None]:
    """dataset/objects.worn_accessory: a ring or a glove is left off a hand on an object, as on a one-hand object
    frame."""
    from darthand.dataset.objects import worn_accessory     # the object modules load only for plans with objects

    return worn_accessory(job)


def _accessory_kind(source, accessory_id: str) -> str:
    return source.accessory_type(accessory_id) or accessory_id.split("_")[0]


def _choose(u: float, n: int) -> int:
    return min(int(u * n), n - 1)


def _non_negative(value, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise InputError(f"{what}: {value!r} must be a non-negative integer")
    return int(value)


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
