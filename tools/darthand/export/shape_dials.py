"""Shape dials: the model's shape directions as blend shapes a DCC user can dial, next to the pose correctives.

A package is built for one shape (`make assets BETAS=...`: the model's template is the shaped surface, the betas
are in model.meta['betas']). Its shape dials are S channels `shape_beta<n>` = delta beta_n, a change of beta n
away from that built shape, over [-range, range] (default 3: the extreme shapes the shape checks test), each
encoded as one or two blend shapes with weights in [0, 1] (`blendshapes.encode_channels`, the correctives' own
encoding), offsets range * shapedirs[:, :, n] in the rest frame. The gesture animations do not drive them (weight
0: the built shape).

Joints. MANO moves the joints with the shape (J = R v_shaped). UsdSkel and glTF cannot: a blend shape moves points
only, and the bind transforms / joint translations / inverse bind matrices are constants of the file. So:

- the skeleton written is the built shape's (joints regressed from the shaped template): with the dials at 0 the
  package poses exactly as `forward(model, pose)` (the export tests check it with UsdSkel and a glTF reader);
- a dialled shape moves the surface and leaves the joints where they were: exact at the rest pose (every skinning
  transform is the identity), but posed, a vertex lands off by about sum_i w_i (R_i - I)(J'_i - J_i), the rotation
  of its joints' displacement. `dial_error` measures that against `forward(model, pose, betas)` over the gestures;
  asset.json / the glTF extras report it. For an exact rig of another shape, build the package for that shape.

Shapes: V vertices, S shape directions, B poses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darthand.errors import InputError
from darthand.export.blendshapes import ShapeEncoding, encode_channels
from darthand.model.forward import forward, pose_feature, skin
from darthand.model.hand_model import HandModel

DIAL_RANGE = 3.0   # |delta beta| a dial reaches at weight 1


@dataclass(frozen=True)
class ShapeDials:
    """The shape channels a package carries. offsets (V, 3, S) = the model's shapedirs (metres per unit beta);
    encoding: the exported blend shapes (weights in [0, 1]); baked (S,) the betas the package was built for;
    value_range: |delta beta| at weight 1 (0: no dials)."""

    offsets: np.ndarray
    encoding: ShapeEncoding
    baked: np.ndarray
    value_range: float

    @property
    def count(self) -> int:
        """Number of exported shape blend shapes (2 per direction, 0 without dials)."""
        return self.encoding.count

    def shape_offsets(self, shapedirs: np.ndarray | None = None) -> np.ndarray:
        """(N, 3, count) blend-shape offsets of shape directions (N, 3, S) (default: the hand's)."""
        return self.encoding.offsets(self.offsets if shapedirs is None else shapedirs)

    def as_dict(self, errors: dict | None = None) -> dict:
        """The record for asset.json / glTF extras: channels, range, baked betas, how joints behave, errors."""
        return {"channels": list(self.encoding.channels), "range": self.value_range,
                "value": "delta beta from the built shape (baked_betas); weights 0 = the built shape",
                "baked_betas": [float(b) for b in self.baked],
                "joints": "the built shape's (exact at weight 0); a dialled shape moves the surface only, not the "
                          "joints (UsdSkel and glTF blend shapes cannot move joints): see dial_error",
                **({"dial_error": errors} if errors else {})}


def shape_dials(model: HandModel, value_range: float = DIAL_RANGE) -> ShapeDials:
    """The dials of `model`'s shape directions over [-value_range, value_range] (0 or a model without shape
    directions: none)."""
    if not np.isfinite(value_range) or value_range < 0:
        raise InputError(f"--shape-dials: the range must be a non-negative number, got {value_range}")
    S = model.num_betas if value_range > 0 else 0
    names = tuple(f"shape_beta{n:02d}" for n in range(S))
    baked = np.zeros(model.num_betas)
    given = np.asarray(model.meta.get("betas", []), dtype=np.float64).reshape(-1)[:model.num_betas]
    baked[:len(given)] = given
    return ShapeDials(model.shapedirs[:, :, :S], encode_channels(names, [-value_range] * S, [value_range] * S),
                      baked, float(value_range))


def dialled_vertices(model: HandModel, poses: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """(B, V, 3) what UsdSkel and glTF compute for poses (B, 48) with the dials at delta beta (S,): the shape
    offsets added to the rest points before skinning, with the built shape's joints (the skinning transforms of
    `forward(model, poses)`)."""
    posed = forward(model, poses)
    d = np.asarray(delta, dtype=np.float64)
    rest = model.v_template + np.einsum("vcs,s->vc", model.shapedirs[:, :, :len(d)], d)
    f = pose_feature(posed.rotations)
    V = model.num_vertices
    offsets = (f @ model.posedirs.transpose(2, 1, 0).reshape(-1, 3 * V)).reshape(len(f), 3, V)
    return skin(np.ascontiguousarray(model.weights.T), posed.transforms, rest.T[None] + offsets)


def dial_error(model: HandModel, dials: ShapeDials, poses: np.ndarray) -> dict:
    """What dialling costs over poses (B, 48): each shape direction at +-range alone, max vertex distance (metres)
    between `dialled_vertices` and `forward(model, poses, delta)` (joints following the shape), and the same for
    the joints' own displacement at rest (how far the skeleton stays behind the dialled surface)."""
    S = dials.offsets.shape[2]
    if S == 0 or not len(poses):
        return {}
    worst, joint_shift = np.zeros(S), np.zeros(S)
    for n in range(S):
        for sign in (1.0, -1.0):
            delta = np.zeros(S)
            delta[n] = sign * dials.value_range
            truth = forward(model, poses, delta[None].repeat(len(poses), 0))
            err = np.linalg.norm(dialled_vertices(model, poses, delta) - truth.vertices, axis=-1).max()
            worst[n] = max(worst[n], err)
            moved = forward(model, np.zeros(48), delta).joints[0] - forward(model, np.zeros(48)).joints[0]
            joint_shift[n] = max(joint_shift[n], np.linalg.norm(moved, axis=-1).max())
    return {"poses": int(len(poses)), "at_range": dials.value_range,
            "max_vertex_error_m": float(worst.max()), "per_direction_m": worst.round(6).tolist(),
            "max_joint_shift_m": float(joint_shift.max())}


def dial_summary(record: dict, lead: str = " +") -> str:
    """' + 20 shape dials (|delta beta| <= 3, posed error <= 4.1 mm)' for a command's report line ('' for none)."""
    if not record.get("channels"):
        return ""
    err = record.get("dial_error", {}).get("max_vertex_error_m")
    tail = f", posed error <= {1000 * err:.1f} mm" if err is not None else ""
    return f"{lead} {2 * len(record['channels'])} shape dials (|delta beta| <= {record['range']:g}{tail})"
