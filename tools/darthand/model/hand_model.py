"""The MANO-layout hand model: one immutable data class and its consistency checks.

Shapes (V vertices, F faces, J = 16 joints, S shape directions, T UV coordinates):

    v_template        (V, 3)       float64, metres, MANO's canonical frame
    faces             (F, 3)       int64, counter-clockwise seen from outside
    weights           (V, J)       float64, rows sum to 1
    posedirs          (V, 3, 135)  float64, corrective offset per pose feature flatten(R_i - I), i = 1..15
    J_regressor       (J, V)       scipy.sparse CSR, joints = J_regressor @ shaped vertices
    parents           (J,)         int64, MANO_PARENTS for a MANO-layout model
    shapedirs         (V, 3, S)    float64, S may be 0
    hands_mean        (45,)        float64, mean finger pose (axis-angle, joints 1..15)
    hands_components  (45, 45)     float64, PCA basis of finger poses (rows are components)
    tip_ids           (5,)         int64, fingertip vertices: thumb, index, middle, ring, pinky
    uvs               (T, 2)       float64 or None, texture coordinates in [0, 1]
    faces_uv          (F, 3)       int64 or None, per-corner indices into `uvs`
    face_labels       (F,)         int8 or None, indices into layout.FACE_LABELS (-1 unlabelled)
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from darthand.errors import InputError
from darthand.model.layout import NUM_JOINTS, NUM_POSE_FEATURES

SIDES = ("right", "left")


@dataclass(frozen=True, eq=False)
class HandModel:
    """A MANO-layout articulated hand. Construct through `HandModel.create` to get a checked instance."""

    v_template: np.ndarray
    faces: np.ndarray
    weights: np.ndarray
    posedirs: np.ndarray
    J_regressor: sp.csr_matrix
    parents: np.ndarray
    shapedirs: np.ndarray
    hands_mean: np.ndarray
    hands_components: np.ndarray
    tip_ids: np.ndarray
    side: str = "right"
    uvs: np.ndarray | None = None
    faces_uv: np.ndarray | None = None
    face_labels: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    @property
    def num_vertices(self) -> int:
        return int(self.v_template.shape[0])

    @property
    def num_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def num_betas(self) -> int:
        return int(self.shapedirs.shape[2])

    @property
    def has_uvs(self) -> bool:
        return self.uvs is not None

    @classmethod
    def create(cls, *, source: str = "model", **fields) -> "HandModel":
        """Coerce dtypes, fill optional fields, check consistency; `source` names the file in error messages."""
        f = dict(fields)
        V = np.asarray(f["v_template"]).shape[0]
        f.setdefault("shapedirs", np.zeros((V, 3, 0)))
        f.setdefault("hands_mean", np.zeros(45))
        f.setdefault("hands_components", np.eye(45))
        f["v_template"] = _float(f["v_template"])
        f["faces"] = _int(f["faces"])
        f["weights"] = _float(f["weights"])
        f["posedirs"] = _float(f["posedirs"])
        f["J_regressor"] = sp.csr_matrix(f["J_regressor"], dtype=np.float64)
        f["parents"] = _int(f["parents"])
        f["shapedirs"] = _float(f["shapedirs"])
        f["hands_mean"] = _float(f["hands_mean"]).reshape(-1)
        f["hands_components"] = _float(f["hands_components"])
        f["tip_ids"] = _int(f["tip_ids"]).reshape(-1)
        for key in ("uvs", "faces_uv", "face_labels"):
            if f.get(key) is not None:
                f[key] = {"uvs": _float, "faces_uv": _int, "face_labels": _int8}[key](f[key])
        f["meta"] = dict(f.get("meta") or {})
        model = cls(**f)
        check_model(model, source)
        return model

    def replace(self, **changes) -> "HandModel":
        """A checked copy with some fields changed."""
        fields = {fld.name: getattr(self, fld.name) for fld in dataclasses.fields(self)}
        fields.update(changes)
        return HandModel.create(source=self.meta.get("source", "model"), **fields)

    def shaped(self, betas) -> "HandModel":
        """The model of one shape, betas (S,): see `model.shape.shaped_model`."""
        from darthand.model.shape import shaped_model
        return shaped_model(self, betas)


def _float(a) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64))


def _int(a) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.int64))


def _int8(a) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.int8))


def check_model(m: HandModel, source: str = "model") -> None:
    """Raise InputError naming `source` and the field if any field has the wrong shape, a non-finite value,
    an out-of-range index, or if the parents do not form a tree rooted at joint 0."""
    V, F = m.v_template.shape[0], m.faces.shape[0]

    def fail(fieldname: str, msg: str):
        raise InputError(f"{source}: field '{fieldname}' {msg}")

    def shape(fieldname: str, arr: np.ndarray, expected: tuple):
        if arr.ndim != len(expected) or any(e is not None and s != e for s, e in zip(arr.shape, expected)):
            want = "x".join("?" if e is None else str(e) for e in expected)
            fail(fieldname, f"has shape {'x'.join(map(str, arr.shape))}, expected {want}")

    def finite(fieldname: str, arr: np.ndarray):
        bad = ~np.isfinite(arr)
        if bad.any():
            idx = np.unravel_index(int(np.argmax(bad)), arr.shape)
            fail(fieldname, f"has a non-finite value ({arr[idx]}) at index {tuple(int(i) for i in idx)}")

    shape("v_template", m.v_template, (None, 3))
    if V < 4:
        fail("v_template", f"has {V} vertices, need at least 4")
    shape("faces", m.faces, (None, 3))
    if F and (m.faces.min() < 0 or m.faces.max() >= V):
        fail("faces", f"indexes vertex {int(m.faces.max() if m.faces.max() >= V else m.faces.min())}, outside 0..{V - 1}")
    shape("weights", m.weights, (V, NUM_JOINTS))
    shape("posedirs", m.posedirs, (V, 3, NUM_POSE_FEATURES))
    shape("J_regressor", m.J_regressor, (NUM_JOINTS, V))
    shape("parents", m.parents, (NUM_JOINTS,))
    shape("shapedirs", m.shapedirs, (V, 3, None))
    shape("hands_mean", m.hands_mean, (45,))
    shape("hands_components", m.hands_components, (None, 45))
    shape("tip_ids", m.tip_ids, (5,))
    for name in ("v_template", "weights", "posedirs", "shapedirs", "hands_mean", "hands_components"):
        finite(name, getattr(m, name))
    finite("J_regressor", m.J_regressor.data)
    if (m.weights < 0).any():
        fail("weights", f"has a negative weight at vertex {int(np.argmax((m.weights < 0).any(1)))}")
    if m.tip_ids.min() < 0 or m.tip_ids.max() >= V:
        fail("tip_ids", f"indexes a vertex outside 0..{V - 1}")
    check_parents(m.parents, source)
    if m.side not in SIDES:
        fail("side", f"is {m.side!r}, expected one of {SIDES}")
    if m.uvs is not None or m.faces_uv is not None:
        if m.uvs is None or m.faces_uv is None:
            fail("uvs", "and 'faces_uv' must be given together")
        shape("uvs", m.uvs, (None, 2))
        finite("uvs", m.uvs)
        shape("faces_uv", m.faces_uv, (F, 3))
        if F and (m.faces_uv.min() < 0 or m.faces_uv.max() >= len(m.uvs)):
            fail("faces_uv", f"indexes a UV outside 0..{len(m.uvs) - 1}")
    if m.face_labels is not None:
        shape("face_labels", m.face_labels, (F,))


def check_parents(parents: np.ndarray, source: str = "model") -> None:
    """Parents must form one tree rooted at joint 0, every parent listed before its child (MANO's order)."""
    if parents[0] != -1:
        raise InputError(f"{source}: field 'parents' must have -1 (no parent) for joint 0, got {int(parents[0])}")
    for i in range(1, len(parents)):
        if not 0 <= parents[i] < i:
            raise InputError(f"{source}: field 'parents' is not a tree in MANO order: joint {i} has parent "
                             f"{int(parents[i])} (must be in 0..{i - 1})")
