"""Hand length and hand breadth measured on rest-pose hand meshes, and the survey statistics they are compared with.

Definitions, after ANSUR II's (hand flat, measured parallel to the hand's axes):

    hand length   from the wrist joint to the most distal point of the middle finger, along the wrist -> middle-MCP
                  axis (ANSUR: distal wrist crease to dactylion; the wrist joint centre lies near that crease, so
                  the two differ by a few millimetres, the same for every shape)
    hand breadth  the extent of the palm along the knuckle line (index MCP -> little-finger MCP), over the skin
                  within KNUCKLE_SLAB times the knuckle line's length of the plane through that line normal to the
                  palm (about 6 mm; relative, so that the measure scales with the hand), thumb excluded
                  (ANSUR: metacarpale II to metacarpale V)

Reference statistics: ANSUR II, the 2012 Anthropometric Survey of U.S. Army Personnel (Gordon, Blackwell,
Bradtmiller et al., NATICK/TR-15/007, 2014; 4,082 men and 1,986 women), summary statistics of `hand length` and
`hand breadth`, rounded here to whole millimetres. They were not downloadable from this project's build machines:
the values are transcribed, not read from the data.
"""

from __future__ import annotations

import numpy as np

from darthand.model.hand_model import HandModel
from darthand.model.layout import FINGER_JOINTS
from darthand.model.per_model import per_model

KNUCKLE_SLAB = 0.09  # half-thickness of the slab the breadth is taken in, relative to the index-pinky MCP distance

# mm, (mean, standard deviation) per sex.
ANSUR_II = {
    "source": "ANSUR II (2012), Gordon et al., NATICK/TR-15/007 (2014), summary statistics, rounded to 1 mm",
    "hand_length_mm": {"female": (181.0, 9.0), "male": (194.0, 9.0)},
    "hand_breadth_mm": {"female": (79.0, 4.0), "male": (89.0, 4.0)},
}


@per_model
def digit_masks(model: HandModel) -> tuple[np.ndarray, np.ndarray]:
    """(V,) bool vertices whose dominant joint is in the middle finger, and in the thumb (read-only, kept per
    model: a dataset frame measures its shape)."""
    dominant = np.argmax(model.weights, axis=1)
    return np.isin(dominant, FINGER_JOINTS["middle"]), np.isin(dominant, FINGER_JOINTS["thumb"])


def hand_length(model: HandModel, vertices: np.ndarray, joints: np.ndarray, masks: tuple | None = None) -> np.ndarray:
    """(B,) hand length (m) of rest-pose vertices (B, V, 3) with joints (B, 16, 3). masks: the model's digit_masks,
    when the caller has them."""
    middle, _ = digit_masks(model) if masks is None else masks
    axis = _unit(joints[:, 0] - joints[:, FINGER_JOINTS["middle"][0]])               # distal -> proximal
    reach = np.einsum("bvc,bc->bv", joints[:, None, 0] - vertices[:, middle], axis)
    return reach.max(axis=1)


def hand_breadth(model: HandModel, vertices: np.ndarray, joints: np.ndarray,
                 masks: tuple | None = None) -> np.ndarray:
    """(B,) hand breadth (m) of rest-pose vertices (B, V, 3) with joints (B, 16, 3). masks: as hand_length's."""
    _, thumb = digit_masks(model) if masks is None else masks
    index, pinky = joints[:, FINGER_JOINTS["index"][0]], joints[:, FINGER_JOINTS["pinky"][0]]
    along = _unit(pinky - index)
    back = np.cross(np.cross(along, joints[:, 0] - index), along)   # in the palm plane, toward the wrist
    normal = _unit(back)
    rel = vertices[:, ~thumb] - index[:, None]
    slab = KNUCKLE_SLAB * np.linalg.norm(pinky - index, axis=-1)
    near = np.abs(np.einsum("bvc,bc->bv", rel, normal)) < slab[:, None]
    t = np.einsum("bvc,bc->bv", rel, along)
    return np.where(near, t, -np.inf).max(1) - np.where(near, t, np.inf).min(1)


def hand_sizes(model: HandModel, vertices: np.ndarray) -> dict:
    """{"hand_length_mm": (B,), "hand_breadth_mm": (B,)} of rest-pose vertices (B, V, 3), joints regressed from
    them."""
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, model.num_vertices, 3)
    joints = np.einsum("jv,bvc->bjc", dense_regressor(model), vertices)
    masks = digit_masks(model)
    return {"hand_length_mm": 1000 * hand_length(model, vertices, joints, masks),
            "hand_breadth_mm": 1000 * hand_breadth(model, vertices, joints, masks)}


@per_model
def dense_regressor(model: HandModel) -> np.ndarray:
    """(16, V) the model's joint regressor as a dense array (read-only, kept per model)."""
    return model.J_regressor.toarray()


def survey_mixture(measure: str, share_male: float = 0.5, survey: dict = ANSUR_II) -> tuple[float, float]:
    """(mean, SD) in mm of a population mixing the survey's women and men, `share_male` of them men."""
    (mf, sf), (mm, sm) = survey[measure]["female"], survey[measure]["male"]
    mean = (1 - share_male) * mf + share_male * mm
    var = (1 - share_male) * (sf ** 2 + (mf - mean) ** 2) + share_male * (sm ** 2 + (mm - mean) ** 2)
    return mean, float(np.sqrt(var))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)
