"""What a frame source gives: the declared interface of the renderer's two sources.

- `assets.HandAssets` (kind 'model'): a model npz (or MANO file) and its catalogues, posed by darthand's forward pass:
  any pose (gesture names, pose files, (48,) axis-angle vectors), any shape (betas), rings worn per pose.
- `usd_source.UsdPackage` (kind 'usd'): a built USD package posed by OpenUSD's UsdSkel: its baked gestures only (by
  name or time code), its baked shape, its variants.

Code that needs to know which can do what asks the interface (`pose_model()`, `gesture_names()`), never the type. A
new kind of source (a glTF package, another engine's rig) implements `FrameSource` and `render.api.open_source`
learns to open it; nothing downstream changes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    from darthand.model.hand_model import HandModel
    from darthand.render.subject import Subject


@runtime_checkable
class FrameSource(Protocol):
    """One hand's frame source (one side).

    kind: 'model' or 'usd'. side: 'right' or 'left'. source: what it was opened from (a path or name), recorded in
    labels. worn_rings: rings slid along the bone per pose (accessories/wear.py) where the source poses the hand
    itself; a source that cannot leaves it False and ignores it.
    """

    kind: str
    source: str
    worn_rings: bool

    @property
    def side(self) -> str: ...

    def pose_model(self) -> HandModel | None:
        """The model frames are posed with (pose vectors, pose files and betas apply to it), or None where the
        source renders baked poses only (a USD package)."""
        ...

    def gesture_names(self) -> list[str]:
        """The named gestures a frame may ask for by name (a model's fitted gestures, a package's baked ones)."""
        ...

    def describe(self) -> dict:
        """What a dataset's writers need of the hand without opening it again: {'source', 'format'} ('usd', or the
        model file's: 'MANO pickle' means its parameters are MANO's), and for a model hands_mean (45,), num_betas,
        vertices, base_vertices."""
        ...

    def texture_ids(self) -> list[str]: ...

    def accessory_ids(self) -> list[str]: ...

    def accessory_type(self, accessory_id: str) -> str | None:
        """The catalogue type of an accessory ('ring', 'watch', ...), or None when the source does not know it."""
        ...

    def relabel(self, name: str) -> None:
        """Record `name` as what the source was opened from (a cluster node opens the driver's file elsewhere)."""
        ...

    def subject(self, pose=None, *, texture: str | None = None, skin_tone_offset: float = 0.0,
                accessory: str | None = None, betas=None, keypoint_order: str = "openpose") -> Subject:
        """The posed hand (and accessory) of one frame: pose None (flat or rest), a gesture name, a pose file, a
        (48,) MANO axis-angle vector relative to the flat hand, or a USD time code; betas (S,) the shape."""
        ...
