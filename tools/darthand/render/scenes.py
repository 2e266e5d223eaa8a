"""What one frame shows, as data: the scene model the renderer and the dataset stage share.

A `Scene` is a tuple of bodies (today one `HandBody`: a skinned hand with its pose, shape, side, appearance and the
accessory it wears), the camera, the lights and the background, plus `record`: what the frame's labels carry that
nothing in the scene draws (the frame index, the gesture's name, the split, the sampling record). The dataset's
jobs (schemas/dataset_jobs.schema.json) are its serialised form: `Scene.from_job(job).to_job() == job` for every
job a plan writes, so a frame's digest and files do not depend on which of the two a stage holds.

Adding a kind of body (a second hand, an object held) adds a dataclass here with its `kind`, its job fields and its
place in `bodies`; a renderer that cannot draw a scene's bodies says so in one line (`Scene.single_hand`).

Units and frames: metres; a pose is MANO axis-angle relative to the flat hand in the source's own frame (a left
hand's pose is the left model's); camera and lights as render/camera.py and render/lights.py read them.
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
_HAND_FIELDS = ("side", "pose", "pose_index", "betas", "texture", "skin_tone_offset", "accessory")
_SCENE_FIELDS = ("camera", "lights", "background")


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

    def pose_value(self):
        """The pose as the renderer takes it: a (48,) float64 array for numbers, else as given."""
        return np.asarray(self.pose, np.float64) if isinstance(self.pose, (list, tuple)) else self.pose


Body = HandBody            # the union of body kinds, one today


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
        return tuple(b for b in self.bodies if b.kind == "hand")

    def single_hand(self) -> HandBody:
        """The scene's one hand; InputError for a scene this renderer cannot draw (no hand, several bodies)."""
        if len(self.bodies) != 1 or not self.hands:
            kinds = ", ".join(b.kind for b in self.bodies) or "nothing"
            raise InputError(f"scene: the renderer draws one hand per frame; this one holds {kinds}")
        return self.hands[0]

    @classmethod
    def from_job(cls, job: dict) -> "Scene":
        """The scene of a dataset job (a checked job dict, dataset/jobs.py)."""
        hand = {k: job[k] for k in _HAND_FIELDS if job.get(k) is not None}
        if isinstance(hand.get("pose"), list):
            hand["pose"] = tuple(hand["pose"])
        if "betas" in hand:
            hand["betas"] = tuple(hand["betas"])
        record = {k: v for k, v in job.items() if k not in _HAND_FIELDS and k not in _SCENE_FIELDS}
        return cls((HandBody(**hand),), job.get("camera", "three_quarter"), job.get("lights"),
                   job.get("background"), record, frozenset(k for k in job if k in _HAND_FIELDS + _SCENE_FIELDS))

    def to_job(self) -> dict:
        """The job of this scene (its one hand's fields, camera, lights, background, record)."""
        hand = self.single_hand()
        values = {"side": hand.side, "pose": list(hand.pose) if isinstance(hand.pose, tuple) else hand.pose,
                  "pose_index": hand.pose_index, "betas": None if hand.betas is None else list(hand.betas),
                  "texture": hand.texture, "skin_tone_offset": hand.skin_tone_offset, "accessory": hand.accessory,
                  "camera": self.camera, "lights": self.lights, "background": self.background}
        job = dict(self.record)
        job.update({k: v for k, v in values.items() if k in self.given})
        return job
