"""What one frame shows, as data: the scene model the renderer and the dataset stage share.

A `Scene` is a tuple of bodies (one or two `HandBody`s: a skinned hand with its pose, shape, side, appearance, the
accessory it wears and its placement; an `ObjectBody`: a catalogue object and its placement), the camera, the
lights and the background, plus `record`: what the frame's labels carry that nothing in the scene draws (the frame
index, the gesture's name, the split, the sampling record). The dataset's jobs (schemas/dataset_jobs.schema.json)
are its serialised form: `Scene.from_job(job).to_job() == job` for every job a plan writes, so a frame's digest and
files do not depend on which of the two a stage holds. A job holds either one hand's fields at its top level or a
`bodies` list (one item per body, with its `kind`), never both.

Adding a kind of body (a second hand, an object held) adds a dataclass here with its `kind`, its job fields and its
place in `bodies`; code that draws one hand only asks `Scene.single_hand`, which refuses others in one line (the
renderer draws scenes of several hands through render/bodies.py).

Units and frames: metres; a pose is MANO axis-angle relative to the flat hand in the source's own frame (a left
hand's pose is the left model's); a body's `placement` (4x4 rigid, row-major) moves it from that frame into the
scene's world frame (None: the identity); camera and lights as render/camera.py and render/lights.py read them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Union

import numpy as np

from darthand.errors import InputError

# A hand's pose: None (the flat hand, or a package's rest pose), a gesture name or a pose file path, a USD package's
# time code, or (48,) MANO axis-angle numbers.
Pose = Union[None, str, int, tuple]

# Job fields a HandBody holds; all other fields of a job are the scene's (camera, lights, background) or its record.
HAND_FIELDS = ("side", "pose", "pose_index", "betas", "texture", "skin_tone_offset", "accessory")
_SCENE_FIELDS = ("camera", "lights", "background")
BODIES = "bodies"
RIGID_TOLERANCE = 1e-6        # how far a placement's rotation part may be from orthonormal (float32 round trips)


@dataclass(frozen=True)
class HandBody:
    """One skinned hand.

    side: 'right', 'left' or None (the source's own side). pose: see `Pose`; pose_index: which pose of a pose file.
    betas: (S,) shape coefficients, None for the source's own shape. texture: a catalogue id (None: the source's
    default); skin_tone_offset: added to the sRGB albedo. accessory: the id of the accessory it wears (attached to
    its joint as the catalogue fits it), None or 'none' for none.
    """

    kind: ClassVar[str] = "hand"

    side: str | None = None
    pose: Pose = None
    pose_index: int | None = None
    betas: tuple | None = None
    texture: str | None = None
    skin_tone_offset: float = 0.0
    accessory: str | None = None
    placement: tuple | None = None
    # Which fields its `bodies` item gave (to_job writes back exactly those); empty for a top-level hand.
    given: frozenset = field(default=frozenset(), compare=False)

    def pose_value(self):
        """The pose as the renderer takes it: a (48,) float64 array for numbers, else as given."""
        return np.asarray(self.pose, np.float64) if isinstance(self.pose, (list, tuple)) else self.pose

    def placement_matrix(self) -> np.ndarray:
        """(4, 4) float64 the rigid transform from the hand's model frame into the world (the identity for None)."""
        return np.eye(4) if self.placement is None else np.asarray(self.placement, np.float64)

    @classmethod
    def from_item(cls, item: dict) -> "HandBody":
        """The hand of one `bodies` item of a job (its 'kind' is 'hand')."""
        values = _hand_values(item)
        if item.get("placement") is not None:
            values["placement"] = tuple(tuple(row) for row in item["placement"])
        return cls(**values, given=frozenset(k for k in item if k != "kind"))

    def to_item(self) -> dict:
        """Its `bodies` item: kind first, then the fields it was read from."""
        values = {**_hand_job_values(self), "placement": None if self.placement is None
                  else [list(row) for row in self.placement]}
        return {"kind": self.kind, **{k: v for k, v in values.items() if k in self.given}}


@dataclass(frozen=True)
class ObjectBody:
    """One rigid object of an object catalogue (objects/loader.py), drawn by render/objects.py.

    object: its catalogue id. placement: (4, 4) rigid, row-major, from the object's frame into the world (None:
    the identity); a held object's is the grasp's, with its hand at the identity.
    """

    kind: ClassVar[str] = "object"

    object: str
    placement: tuple | None = None
    given: frozenset = field(default=frozenset(), compare=False)

    def placement_matrix(self) -> np.ndarray:
        """(4, 4) float64 the rigid transform from the object's frame into the world (the identity for None)."""
        return np.eye(4) if self.placement is None else np.asarray(self.placement, np.float64)

    @classmethod
    def from_item(cls, item: dict) -> "ObjectBody":
        """The object of one `bodies` item of a job (its 'kind' is 'object')."""
        placement = item.get("placement")
        return cls(item["object"], None if placement is None else tuple(tuple(row) for row in placement),
                   frozenset(k for k in item if k != "kind"))

    def to_item(self) -> dict:
        """Its `bodies` item: kind first, then the fields it was read from."""
        values = {"object": self.object,
                  "placement": None if self.placement is None else [list(row) for row in self.placement]}
        return {"kind": self.kind, **{k: v for k, v in values.items() if k in self.given}}


Body = Union[HandBody, ObjectBody]          # the body kinds
BODY_KINDS: dict[str, type[HandBody] | type[ObjectBody]] = {HandBody.kind: HandBody, ObjectBody.kind: ObjectBody}


def _hand_values(fields: dict) -> dict:
    """HandBody's keyword values of a job's (or a bodies item's) hand fields (None values left out)."""
    hand = {k: fields[k] for k in HAND_FIELDS if fields.get(k) is not None}
    if isinstance(hand.get("pose"), list):
        hand["pose"] = tuple(hand["pose"])
    if "betas" in hand:
        hand["betas"] = tuple(hand["betas"])
    return hand


def _hand_job_values(hand: HandBody) -> dict:
    """The job values of a hand's fields (lists where the body holds tuples)."""
    return {"side": hand.side, "pose": list(hand.pose) if isinstance(hand.pose, tuple) else hand.pose,
            "pose_index": hand.pose_index, "betas": None if hand.betas is None else list(hand.betas),
            "texture": hand.texture, "skin_tone_offset": hand.skin_tone_offset, "accessory": hand.accessory}


def rigid_error(value) -> str | None:
    """Why `value` is not a 4x4 rigid transform (row-major nested lists, rotation orthonormal with det +1, last row
    0 0 0 1), or None when it is one."""
    try:
        m = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        return "is not a 4x4 matrix of numbers"
    if m.shape != (4, 4) or not np.isfinite(m).all():
        return "is not a 4x4 matrix of finite numbers"
    R = m[:3, :3]
    if np.abs(R @ R.T - np.eye(3)).max() > RIGID_TOLERANCE or np.linalg.det(R) < 0:
        return "is not a rigid transform (its 3x3 part must be a rotation: orthonormal, det +1)"
    if np.abs(m[3] - [0, 0, 0, 1]).max() > RIGID_TOLERANCE:
        return "is not a rigid transform (its last row must be 0 0 0 1)"
    return None


@dataclass(frozen=True)
class Scene:
    """One frame's content: bodies, camera (a view name, a camera file path or document; None: three_quarter),
    lights (None: the renderer's default rig, a lights file path or document), background (None, an image path, or
    a dataset's background document, dataset/backgrounds.py), record (labels-only fields, see the module
    docstring)."""

    bodies: tuple
    camera: str | dict | None = "three_quarter"
    lights: str | dict | None = None
    background: str | dict | None = None
    record: dict = field(default_factory=dict)
    # Which of the job's optional fields were given (so that to_job writes back exactly the job it was read from).
    given: frozenset = frozenset()

    @property
    def hands(self) -> tuple:
        return tuple(b for b in self.bodies if b.kind == HandBody.kind)

    @property
    def objects(self) -> tuple:
        return tuple(b for b in self.bodies if b.kind == ObjectBody.kind)

    def single_hand(self) -> HandBody:
        """The scene's one hand, for code that draws one (the Cycles tier, the studio); InputError for a scene of no
        hand or several bodies."""
        if len(self.bodies) != 1 or not self.hands:
            kinds = ", ".join(b.kind for b in self.bodies) or "nothing"
            raise InputError(f"scene: one hand per frame here; this one holds {kinds}")
        return self.hands[0]

    @classmethod
    def from_job(cls, job: dict) -> "Scene":
        """The scene of a dataset job (a checked job dict, dataset/jobs.py): its top-level hand, or its `bodies`."""
        body_fields = (BODIES,) if BODIES in job else HAND_FIELDS
        if BODIES in job:
            bodies = tuple(_body_of_item(item) for item in job[BODIES])
        else:
            bodies = (HandBody(**_hand_values(job)),)
        record = {k: v for k, v in job.items() if k not in body_fields and k not in _SCENE_FIELDS}
        return cls(bodies, job.get("camera", "three_quarter"), job.get("lights"), job.get("background"), record,
                   frozenset(k for k in job if k in body_fields + _SCENE_FIELDS))

    def to_job(self) -> dict:
        """The job of this scene (its hand's fields or its bodies, camera, lights, background, record)."""
        values: dict = {"camera": self.camera, "lights": self.lights, "background": self.background}
        if BODIES in self.given:
            values[BODIES] = [body.to_item() for body in self.bodies]
        else:
            values.update(_hand_job_values(self.single_hand()))
        job = dict(self.record)
        job.update({k: v for k, v in values.items() if k in self.given})
        return job


def _body_of_item(item: dict) -> Body:
    """The body of one `bodies` item, by its kind (InputError for a kind this version does not know)."""
    kind = BODY_KINDS.get(str(item.get("kind")))
    if kind is None:
        raise InputError(f"bodies: unknown body kind {item.get('kind')!r} (known: {', '.join(BODY_KINDS)})")
    return kind.from_item(item)
