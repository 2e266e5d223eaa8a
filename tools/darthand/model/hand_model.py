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
import weakref
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from darthand.errors import InputError
from darthand.model.layout import FACE_LABELS, NUM_JOINTS, NUM_POSE_FEATURES
from darthand.model.shape import check_betas, shaped_vertices

SIDES = ("right", "left")
# Largest magnitude a float field may hold: a hand in metres is far below it, and products of such values stay finite.
MAX_MAGNITUDE = 1e6


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
        V = np.shape(f["v_template"])[0] if np.ndim(f["v_template"]) else 0
        f.setdefault("shapedirs", np.zeros((V, 3, 0)))
        f.setdefault("hands_mean", np.zeros(45))
        f.setdefault("hands_components", np.eye(45))
        kinds = dict.fromkeys(("v_template", "weights", "posedirs", "shapedirs", "hands_mean", "hands_components",
                               "uvs"), _float)
        kinds.update(dict.fromkeys(("faces", "parents", "tip_ids", "faces_uv"), _int), face_labels=_int8)
        for key, convert in kinds.items():
            if f.get(key) is not None:
                f[key] = _converted(convert, f[key], key, source)
        f["hands_mean"] = f["hands_mean"].reshape(-1)
        f["tip_ids"] = f["tip_ids"].reshape(-1)
        f["J_regressor"] = _sparse(f["J_regressor"], source)
        if not isinstance(f.get("meta") or {}, dict):
            raise InputError(f"{source}: field 'meta' is a {type(f['meta']).__name__}, expected a dict")
        f["meta"] = dict(f.get("meta") or {})
        model = cls(**f)
        check_model(model, source)
        _CHECKED.add(model)
        return model

    def replace(self, **changes) -> "HandModel":
        """A checked copy with some fields changed."""
        fields = {fld.name: getattr(self, fld.name) for fld in dataclasses.fields(self)}
        fields.update(changes)
        return HandModel.create(source=self.meta.get("source", "model"), **fields)

    def shaped(self, betas) -> "HandModel":
        """The model of one shape, betas (S,): template = `shape.shaped_vertices`, everything else kept; the betas
        are recorded in meta['betas'] (added to any already baked in)."""
        b = check_betas(self, betas)
        if b.ndim != 1:
            raise InputError(f"betas: one shape expected, got shape {b.shape}")
        baked = np.zeros(self.num_betas)
        baked[:len(b)] = b
        previous = np.asarray(self.meta.get("betas", np.zeros(self.num_betas)), dtype=np.float64)
        if previous.shape == baked.shape:
            baked = baked + previous
        meta = {**self.meta, "betas": baked.tolist()}
        if self not in _CHECKED:
            return self.replace(v_template=shaped_vertices(self, b), meta=meta)
        # Only the template is new: every other field passed check_model with this model (1 ms a refit saved).
        source = self.meta.get("source", "model")
        v_template = _converted(_float, shaped_vertices(self, b), "v_template", source)
        check_finite(source, "v_template", v_template)
        model = dataclasses.replace(self, v_template=v_template, meta=meta)
        _CHECKED.add(model)
        return model


_CHECKED: "weakref.WeakSet[HandModel]" = weakref.WeakSet()     # models made by create (check_model passed)


def _converted(convert, value, key: str, source: str) -> np.ndarray:
    """convert(value), with the dtype checked first: numbers (and booleans) only, so strings, objects and complex
    values are refused by name instead of being cast."""
    a = value if isinstance(value, np.ndarray) else np.asarray(value)
    kinds = "biu" if convert is not _float else "biuf"
    if a.dtype.kind not in kinds:
        want = "integer" if convert is not _float else "real number"
        raise InputError(f"{source}: field '{key}' has dtype {a.dtype}, expected {want}s")
    if convert is not _float and a.size and (a.min() < np.iinfo(np.int64).min or a.max() > np.iinfo(np.int64).max):
        raise InputError(f"{source}: field '{key}' holds an integer outside the 64-bit range")
    return convert(a)


def _sparse(value, source: str) -> sp.csr_matrix:
    """A checked float64 CSR copy: shape, index dtypes, index bounds and indptr order (`check_format(full_check)`),
    so a matrix product never reads outside its arrays."""
    try:
        m = sp.csr_matrix(value, dtype=np.float64)
        m.check_format(full_check=True)
    except (ValueError, TypeError, IndexError, OverflowError) as e:
        raise InputError(f"{source}: field 'J_regressor' is not a valid sparse matrix ({str(e)[:120]})") from None
    return m


def _float(a) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64))


def _int(a) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.int64))


def _int8(a) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.int8))


def check_finite(source: str, fieldname: str, arr: np.ndarray) -> None:
    """InputError naming `source` and the field at the first value of `arr` that is not finite or beyond
    +-MAX_MAGNITUDE."""
    if not arr.size or arr.min() >= -MAX_MAGNITUDE and arr.max() <= MAX_MAGNITUDE:
        return          # every value within the bounds (a NaN makes min and max NaN): two fast reductions
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(arr) <= MAX_MAGNITUDE)
    if bad.any():
        idx = np.unravel_index(int(np.argmax(bad)), arr.shape)
        what = "a non-finite value" if not np.isfinite(arr[idx]) else f"a value beyond +-{MAX_MAGNITUDE:g}"
        raise InputError(f"{source}: field '{fieldname}' has {what} ({arr[idx]}) at index "
                         f"{tuple(int(i) for i in idx)}")


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

    shape("v_template", m.v_template, (None, 3))
    if V < 4:
        fail("v_template", f"has {V} vertices, need at least 4")
    shape("faces", m.faces, (None, 3))
    if F and (m.faces.min() < 0 or m.faces.max() >= V):
        outside = int(m.faces.max() if m.faces.max() >= V else m.faces.min())
        fail("faces", f"indexes vertex {outside}, outside 0..{V - 1}")
    shape("weights", m.weights, (V, NUM_JOINTS))
    shape("posedirs", m.posedirs, (V, 3, NUM_POSE_FEATURES))
    shape("J_regressor", m.J_regressor, (NUM_JOINTS, V))
    shape("parents", m.parents, (NUM_JOINTS,))
    shape("shapedirs", m.shapedirs, (V, 3, None))
    shape("hands_mean", m.hands_mean, (45,))
    shape("hands_components", m.hands_components, (None, 45))
    shape("tip_ids", m.tip_ids, (5,))
    for name in ("v_template", "weights", "posedirs", "shapedirs", "hands_mean", "hands_components"):
        check_finite(source, name, getattr(m, name))
    check_finite(source, "J_regressor", m.J_regressor.data)
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
        assert m.uvs is not None and m.faces_uv is not None
        shape("uvs", m.uvs, (None, 2))
        check_finite(source, "uvs", m.uvs)
        shape("faces_uv", m.faces_uv, (F, 3))
        if F and (m.faces_uv.min() < 0 or m.faces_uv.max() >= len(m.uvs)):
            fail("faces_uv", f"indexes a UV outside 0..{len(m.uvs) - 1}")
    if m.face_labels is not None:
        shape("face_labels", m.face_labels, (F,))
        if F and (m.face_labels.min() < -1 or m.face_labels.max() >= len(FACE_LABELS)):
            fail("face_labels", f"holds a label outside -1..{len(FACE_LABELS) - 1}")
    check_meta(m.meta, source)


# Known metadata keys and what their values must be (other keys are kept as they are).
META_TYPES = {"source": str, "fixes": list, "warnings": list, "wrist": dict, "wrist_uv_band": list,
              "uv_atlas": dict, "provenance": dict, "correctives": dict, "mirrored_from": str}
WRIST_INTS = ("rings", "ring_size", "base_vertices", "base_faces", "anchor")


def check_meta(meta: dict, source: str = "model") -> None:
    """The metadata keys darthand reads have the types it reads them as (meta_json comes from the file)."""
    def fail(key: str, msg: str):
        raise InputError(f"{source}: field 'meta.{key}' {msg}")

    for key, kind in META_TYPES.items():
        if key in meta and not isinstance(meta[key], kind):
            fail(key, f"is a {type(meta[key]).__name__}, expected a {kind.__name__}")
    for key in ("fixes", "warnings"):
        if not all(isinstance(x, str) for x in meta.get(key, [])):
            fail(key, "must be a list of strings")
    wrist = meta.get("wrist", {})
    for key in WRIST_INTS:
        if key in wrist and not (isinstance(wrist[key], int) and 0 <= wrist[key] < 1 << 31):
            fail(f"wrist.{key}", f"is {str(wrist[key])[:40]}, expected a non-negative integer")
    band = meta.get("wrist_uv_band")
    if band is not None and not (len(band) == 4 and all(isinstance(x, (int, float)) and 0 <= x <= 1 for x in band)):
        fail("wrist_uv_band", "must be four numbers in [0, 1] (u0, v0, u1, v1)")


def check_parents(parents: np.ndarray, source: str = "model") -> None:
    """Parents must form one tree rooted at joint 0, every parent listed before its child (MANO's order)."""
    if parents[0] != -1:
        raise InputError(f"{source}: field 'parents' must have -1 (no parent) for joint 0, got {int(parents[0])}")
    for i in range(1, len(parents)):
        if not 0 <= parents[i] < i:
            raise InputError(f"{source}: field 'parents' is not a tree in MANO order: joint {i} has parent "
                             f"{int(parents[i])} (must be in 0..{i - 1})")
