"""The drawn surfaces of a frame beyond the model's own mesh: `GeometryOptions` (Loop subdivision of the skin, an arm
that goes on past the forearm cut) and `Dresser`, which applies them to a posed subject once its camera is known.

Both options leave what the labels say about the hand as it was: the subject keeps the model's own posed vertices
(Subject.mesh) for the labels' thickness test and the dataset's meshes, and the camera stays framed on the plain
subject (Subject.framing). Both are off by default, and a frame rendered with them off is the frame rendered before
they existed.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from darthand.errors import InputError
from darthand.jit import kernel
from darthand.model.topology import vertex_normals
from darthand.render.arm import ARM, ARM_END, check_length, shorten_before
from darthand.render.camera import Camera
from darthand.render.subdivision import MAX_LEVEL, SMOOTHED_ROLES, Subdivider
from darthand.render.subject import Subject

CAMERA_CLEARANCE_M = 0.02     # a camera this near the arm's surface counts as inside it


@dataclass(frozen=True)
class GeometryOptions:
    """subdivision: Loop levels applied to the skin at render time (0 off, 1 or 2; render/subdivision.py). arm:
    metres of forearm drawn past the cut in place of its flat cap (0 off; render/arm.py)."""

    subdivision: int = 0
    arm: float = 0.0

    def __post_init__(self) -> None:
        if not (isinstance(self.subdivision, (int, np.integer)) and 0 <= self.subdivision <= MAX_LEVEL):
            raise InputError(f"subdivision: {self.subdivision!r} is not a level in 0..{MAX_LEVEL}")
        if self.arm:
            check_length(self.arm)

    @property
    def is_default(self) -> bool:
        return self == GeometryOptions()

    def to_json(self) -> dict:
        """The options that differ from the defaults (empty when none does: a default frame's records are as they
        were before these options existed)."""
        out: dict = {}
        if self.subdivision:
            out["subdivision"] = int(self.subdivision)
        if self.arm:
            out["arm"] = float(self.arm)
        return out


def geometry_options(value=None, **fields) -> GeometryOptions:
    """GeometryOptions from None (the defaults), an instance, or a dict of its fields, with `fields` (None values
    ignored) on top (InputError naming an unknown field or a bad value)."""
    if value is None:
        value = {}
    if isinstance(value, GeometryOptions):
        value = dataclasses.asdict(value)
    if not isinstance(value, dict):
        raise InputError(f"geometry: expected GeometryOptions or a dict, got {type(value).__name__}")
    merged = {**value, **{k: v for k, v in fields.items() if v is not None}}
    unknown = sorted(set(merged) - set(GeometryOptions.__dataclass_fields__))
    if unknown:
        raise InputError(f"geometry: unknown option {unknown[0]!r} (known: subdivision, arm)")
    return GeometryOptions(**merged)


class Dresser:
    """Applies GeometryOptions to posed subjects, keeping the subdivision plans of the topologies it has seen."""

    def __init__(self) -> None:
        self.subdivider = Subdivider()

    def dress(self, subject: Subject, camera: Camera, options: GeometryOptions) -> Subject:
        """The subject as drawn: an arm kept out of the camera (`clear_of_camera`), its skin surfaces subdivided
        (the labels then trace visibility against the unsubdivided surfaces: Subject.labelled); the same subject
        when both options are off."""
        if options.is_default:
            return subject
        surfaces = clear_of_camera(subject.surfaces, camera)
        labelled = None
        if options.subdivision:
            labelled = dataclasses.replace(subject, surfaces=surfaces)
            surfaces = tuple(self.subdivider.surface(s, options.subdivision) if smoothed(s) else s for s in surfaces)
        info = {**subject.info, "geometry": options.to_json()}
        base = subject.info.get("base_faces")
        if base is not None and options.subdivision:
            info["base_faces"] = int(base) * 4 ** options.subdivision       # face f's children: 4^k f ...
        return dataclasses.replace(subject, surfaces=surfaces, info=info, mesh=subject.hand_vertices,
                                   framing=subject.framing_points(), labelled=labelled)


def smoothed(surface) -> bool:
    """Whether a surface is subdivided: the skin (SMOOTHED_ROLES) and a skinned accessory (a glove: a rigid one has
    a `transform`), which lies a millimetre off the skin and must move with it (subdividing the skin alone would
    push its concave parts, between the fingers and in the palm, through the glove)."""
    return surface.role in SMOOTHED_ROLES or (surface.role == "accessory" and surface.transform is None)


def model_coverage(alpha: np.ndarray, geom: np.ndarray, surfaces: tuple) -> np.ndarray:
    """(H, W) float32 the coverage `alpha` (H, W) of the model's surfaces alone (hand, its cut's cap, accessory):
    the pixels whose centre ray hit an arm surface (render/arm.py, `geom` (H, W) the surface index) left out, and
    the background-centred edge pixels kept only beside a pixel of the model. The mask, bbox and coverage then mean
    what they meant before the arm (`alpha` itself, without an arm). A held object's pixels (role 'object') are
    left out likewise: the mask is the hand's (the object's is in the instance map). Beside: one of the 8
    neighbours (scipy's binary_dilation with a 3 x 3 square). alpha's bits are copied where kept, 0 elsewhere."""
    arm = [i for i, s in enumerate(surfaces) if s.name in (ARM, ARM_END) or s.role == "object"]
    if not arm:
        return alpha
    geom = np.ascontiguousarray(geom, np.int8)          # as the frame's geom map holds it (a traced int32 one too)
    model = geom >= 0
    for index in arm:                   # a comparison per left-out surface (one to three): cheaper than np.isin's
        model &= geom != index
    out = np.empty(alpha.shape, np.float32)
    _coverage_kernel(np.ascontiguousarray(alpha, np.float32), geom, model.view(np.uint8), out)
    return out


@kernel
def _coverage_kernel(alpha, geom, model, out):
    """out (H, W) float32 = alpha's value where model (H, W) uint8 0/1 is set, or where geom (H, W) int8 is
    background (< 0) with a model pixel among its 8 neighbours, else 0. Per row: the column-wise OR
    of the model's three rows (clamped at the frame's edges: a row repeated changes no OR), then each pixel's
    three of it, in 0/1 arithmetic (no branch to keep the loop from vectorising)."""
    H, W = alpha.shape
    near = np.zeros(W + 2, np.uint8)
    zero = np.float32(0.0)
    for r in range(H):
        up, down = max(r - 1, 0), min(r + 1, H - 1)
        for c in range(W):
            near[c + 1] = model[up, c] | model[r, c] | model[down, c]
        for c in range(W):
            keep = model[r, c] | (np.uint8(geom[r, c] < 0) & (near[c] | near[c + 1] | near[c + 2]))
            out[r, c] = alpha[r, c] if keep else zero


def clear_of_camera(surfaces: tuple, camera: Camera) -> tuple:
    """The surfaces with an arm (render/arm.py: its tube, role 'arm', and its far end, ARM_END) cut back by
    arm.shorten_before when the camera looks along it from inside its half-cylinder; the same tuple otherwise. The
    axis runs from the tube's first ring's centre to the far end's centre (the end's last vertex; its ring is its
    other vertices)."""
    tube = next((s for s in surfaces if s.role == "arm"), None)
    end = next((s for s in surfaces if s.name == ARM_END), None)
    if tube is None or end is None:
        return surfaces
    ring = len(end.vertices) - 1
    origin = tube.vertices[:ring].astype(np.float64).mean(0)
    axis = end.vertices[-1].astype(np.float64) - origin
    axis /= max(float(np.linalg.norm(axis)), 1e-9)
    rel = tube.vertices - origin
    radius = float(np.linalg.norm(rel - np.outer(rel @ axis, axis), axis=1).max()) + CAMERA_CLEARANCE_M
    moved = {}
    for s in (tube, end):
        v = shorten_before(s.vertices, origin, axis, camera.centre, radius, float((end.vertices[-1] - origin) @ axis),
                           tube.vertices[:ring].astype(np.float64))
        if v is not s.vertices:
            moved[s.name] = dataclasses.replace(s, vertices=v, normals=vertex_normals(v, s.faces))
    return surfaces if not moved else tuple(moved.get(s.name, s) for s in surfaces)
