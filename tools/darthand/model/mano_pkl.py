"""Loader for the official MANO pickles (MANO_RIGHT.pkl / MANO_LEFT.pkl), without chumpy and without running code.

The official files are Python 2 pickles of a dict (read with ``encoding='latin1'``)::

    v_template        (778, 3)        float64, metres
    f                 (1538, 3)       uint32 faces
    weights           (778, 16)       skinning weights
    posedirs          (778, 3, 135)   pose correctives
    shapedirs         (778, 3, 10)    a chumpy ``Ch`` (sometimes a ``Select`` over one) holding the array
    J_regressor       (16, 778)       scipy CSC matrix
    kintree_table     (2, 16)         row 0 parents (root: 2**32 - 1), row 1 joint ids
    hands_components  (45, 45), hands_mean (45,), hands_coeffs, J (16, 3), bs_style 'lbs', bs_type 'lrotmin'

A pickle can call any importable function while it loads, so it is read by `safe_pickle.read_pickle` with
`ALLOWED_GLOBALS`: safe_pickle's numpy and builtin guards plus small stand-ins for scipy's sparse classes and chumpy's
classes that only record their pickled state; everything else raises `UnsafePickleError` at the moment the global is
looked up, before it can be called. chumpy itself is never imported (it does not import on modern numpy); its
objects are evaluated from their recorded state (`Ch.x`, `Select.a[idxs]`, ...) into float64 arrays.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.sparse as sp

from darthand.errors import InputError
from darthand.model.hand_model import HandModel, check_parents
from darthand.model.layout import FINGER_JOINTS, FINGERS, MANO_TIP_IDS, NUM_JOINTS, NUM_POSE_FEATURES
from darthand.safe_pickle import BASE_GLOBALS, Guard, StandIn, first_line, printable, read_pickle

MANO_NUM_VERTICES = 778
MANO_FORMAT = "MANO pickle"       # meta["format"] of a model read from a MANO file (datasets record it); in errors
LEFT_SHAPEDIRS_FIX = "left shapedirs x sign flipped"
# |Pearson correlation| above which an axis counts in the left-shapedirs test (see `shapedirs_x_sign_wrong`).
_DECISIVE_CORRELATION = 0.5


# --------------------------------------------------------------------------------------------------------------------
# Stand-ins for chumpy and scipy.sparse objects: they record their pickled state and nothing else.


class _Chumpy(StandIn):
    """A chumpy node; `value` evaluates it from its recorded terms (chumpy drops its caches when pickling)."""

    __slots__ = ()

    def value(self, seen: frozenset) -> np.ndarray:
        raise NotImplementedError


class _ChumpyCh(_Chumpy):
    __slots__ = ()
    qualname = "chumpy.ch.Ch"

    def value(self, seen):
        return evaluate(self.term("x"), seen)


class _ChumpySelect(_Chumpy):
    """chumpy's `a[key]`: the flat indices `idxs` into `a`, reshaped to `preferred_shape`."""

    __slots__ = ()
    qualname = "chumpy.reordering.Select"

    def value(self, seen):
        a = evaluate(self.term("a"), seen)
        idxs = np.asarray(evaluate(self.term("idxs"), seen)).reshape(-1)
        if idxs.dtype.kind not in "iu":
            raise ValueError(f"{self.qualname} has non-integer idxs ({idxs.dtype})")
        shape = self.state.get("preferred_shape", (idxs.size,))
        return a.reshape(-1)[idxs].reshape(tuple(int(n) for n in shape))


class _ChumpyReshape(_Chumpy):
    __slots__ = ()
    qualname = "chumpy.reordering.Reshape"

    def value(self, seen):
        return evaluate(self.term("a"), seen).reshape(self.term("newshape"))


class _ChumpyRavel(_Chumpy):
    __slots__ = ()
    qualname = "chumpy.reordering.Ravel"

    def value(self, seen):
        return evaluate(self.term("a"), seen).reshape(-1)


class _ChumpyTranspose(_Chumpy):
    __slots__ = ()
    qualname = "chumpy.reordering.Transpose"

    def value(self, seen):
        return np.transpose(evaluate(self.term("a"), seen), axes=self.state.get("axes"))


class _Sparse(StandIn):
    """A pickled scipy compressed sparse matrix; rebuilt from its parts and fully checked before use."""

    __slots__ = ()
    format = "csc"

    def matrix(self) -> sp.spmatrix:
        shape = self.state.get("_shape", self.state.get("shape"))
        if shape is None:
            raise ValueError(f"{self.qualname} has no shape")
        parts = tuple(np.asarray(self.term(k)) for k in ("data", "indices", "indptr"))
        cls = sp.csc_matrix if self.format == "csc" else sp.csr_matrix
        m = cls(parts, shape=tuple(int(n) for n in shape))
        m.check_format(full_check=True)  # out-of-range indices would make later conversions read out of bounds
        return m


class _SparseCsc(_Sparse):
    __slots__ = ()
    qualname = "scipy.sparse.csc_matrix"
    format = "csc"


class _SparseCsr(_Sparse):
    __slots__ = ()
    qualname = "scipy.sparse.csr_matrix"
    format = "csr"


def evaluate(obj, seen: frozenset = frozenset()) -> np.ndarray:
    """The array a pickled value stands for: ndarrays as they are, chumpy stand-ins evaluated, lists converted."""
    if isinstance(obj, _Chumpy):
        if id(obj) in seen:
            raise ValueError(f"{obj.qualname} refers to itself")
        return np.asarray(obj.value(seen | {id(obj)}))
    if isinstance(obj, _Sparse):
        return obj.matrix().toarray()
    if isinstance(obj, (StandIn, Guard)):
        raise ValueError(f"{obj!r} is not an array")
    return np.asarray(obj)


# --------------------------------------------------------------------------------------------------------------------
# The allow-list.

#: Every global a MANO pickle may reference, by the exact (module, name) written in the file.
ALLOWED_GLOBALS = {
    **BASE_GLOBALS,
    ("scipy.sparse.csc", "csc_matrix"): _SparseCsc,
    ("scipy.sparse._csc", "csc_matrix"): _SparseCsc,
    ("scipy.sparse.csr", "csr_matrix"): _SparseCsr,
    ("scipy.sparse._csr", "csr_matrix"): _SparseCsr,
    ("chumpy.ch", "Ch"): _ChumpyCh,
    ("chumpy.reordering", "Select"): _ChumpySelect,
    ("chumpy.reordering", "Reshape"): _ChumpyReshape,
    ("chumpy.reordering", "Ravel"): _ChumpyRavel,
    ("chumpy.reordering", "Transpose"): _ChumpyTranspose,
}


def is_mano_pkl(path: str | Path) -> bool:
    """True if `path` is a file whose first bytes look like a pickle (protocol 2-5 header, or a protocol 0/1 dict).

    A cheap dispatch test; it reads two bytes and never unpickles. `load_mano_pkl` does the real checks.
    """
    try:
        with open(path, "rb") as f:
            head = f.read(2)
    except OSError:
        return False
    return (len(head) == 2 and head[0] == 0x80 and 2 <= head[1] <= 5) or head[:1] in (b"(", b"}")


# --------------------------------------------------------------------------------------------------------------------
# From the pickled dict to checked plain arrays.

_REQUIRED = ("v_template", "f", "weights", "posedirs", "shapedirs", "J_regressor", "kintree_table",
             "hands_components", "hands_mean")
# field -> (expected shape, accepted dtype kinds); "V" is the vertex count of v_template, None any size.
_FIELDS = {
    "v_template": (("V", 3), "fiu"),
    "f": ((None, 3), "iu"),
    "weights": (("V", NUM_JOINTS), "fiu"),
    "posedirs": (("V", 3, NUM_POSE_FEATURES), "fiu"),
    "shapedirs": (("V", 3, None), "fiu"),
    "kintree_table": ((2, NUM_JOINTS), "iu"),
    "hands_components": ((None, 45), "fiu"),
    "hands_mean": ((45,), "fiu"),
}
_EXPECTED_TEXT = {"bs_style": "lbs", "bs_type": "lrotmin"}


def _field_array(raw: dict, key: str, path: Path) -> np.ndarray:
    try:
        arr = evaluate(raw[key])
    except (ValueError, TypeError, IndexError, RecursionError) as e:
        raise InputError(f"{path}: field '{key}' cannot be read as an array ({first_line(e)})") from None
    return arr


def _check_array(arr: np.ndarray, key: str, V: int | None, path: Path) -> np.ndarray:
    """`arr` as float64 (int64 for integer fields) after checking its dtype kind, shape and finiteness."""
    expected, kinds = _FIELDS[key]
    if arr.dtype.kind not in kinds:
        raise InputError(f"{path}: field '{key}' has dtype {arr.dtype}, expected {_kind_names(kinds)}")
    want = tuple(V if e == "V" else e for e in expected)
    if arr.ndim != len(want) or any(e is not None and s != e for s, e in zip(arr.shape, want)):
        shape = "x".join(map(str, arr.shape)) or "()"
        raise InputError(f"{path}: field '{key}' has shape {shape}, expected "
                         + "x".join("?" if e is None else str(e) for e in want))
    _check_finite(arr, key, path)
    return arr.astype(np.int64 if kinds == "iu" else np.float64)


def _check_finite(arr: np.ndarray, key: str, path: Path) -> None:
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        idx = np.unravel_index(int(np.argmax(~np.isfinite(arr))), arr.shape)
        raise InputError(f"{path}: field '{key}' has a non-finite value ({arr[idx]}) at index "
                         f"{tuple(int(i) for i in idx)}")


def _kind_names(kinds: str) -> str:
    return "an integer array" if kinds == "iu" else "a numeric array"


def _regressor(raw: dict, V: int, path: Path) -> sp.csr_matrix:
    value = raw["J_regressor"]
    try:
        matrix = value.matrix() if isinstance(value, _Sparse) else sp.csr_matrix(evaluate(value))
    except (ValueError, TypeError, IndexError, RecursionError) as e:
        raise InputError(f"{path}: field 'J_regressor' is not a valid sparse matrix ({first_line(e)})") from None
    matrix = sp.csr_matrix(matrix, dtype=np.float64)
    if matrix.shape != (NUM_JOINTS, V):
        raise InputError(f"{path}: field 'J_regressor' has shape {matrix.shape[0]}x{matrix.shape[1]}, "
                         f"expected {NUM_JOINTS}x{V}")
    _check_finite(matrix.data, "J_regressor", path)
    return matrix


def parents_from_kintree(kintree: np.ndarray, path: str | Path = "model") -> np.ndarray:
    """(J,) int64 parents from MANO's (2, J) kintree_table (row 0 parents, row 1 joint ids).

    The root's parent is stored as 2**32 - 1 (an unsigned -1); any value outside 0..J-1 counts as "no parent",
    and `check_parents` then insists that only joint 0 has none and that every parent precedes its child.
    """
    table = np.asarray(kintree).astype(np.int64)
    J = table.shape[1]
    ids, parent_ids = table[1], table[0]
    if not np.array_equal(np.sort(ids), np.arange(J)):
        raise InputError(f"{path}: field 'kintree_table' row 1 (joint ids) is not a permutation of 0..{J - 1}")
    parents = np.empty(J, dtype=np.int64)
    parents[ids] = np.where((parent_ids >= 0) & (parent_ids < J), parent_ids, -1)
    check_parents(parents, f"{path} (kintree_table)")
    return parents


def _check_text_fields(raw: dict, path: Path) -> None:
    """bs_style/bs_type, when present, must be MANO's linear blend skinning with lrotmin pose features."""
    for key, expected in _EXPECTED_TEXT.items():
        if key in raw:
            value = raw[key].decode("latin1") if isinstance(raw[key], bytes) else raw[key]
            if value != expected:
                raise InputError(f"{path}: field '{key}' is {printable(repr(value), 60)}, this loader supports "
                                 f"only '{expected}'")


# --------------------------------------------------------------------------------------------------------------------
# Side, fingertips and the MANO_LEFT shapedirs bug.


def side_from_joints(joints: np.ndarray) -> str | None:
    """'right' or 'left' from rest joints (16, 3) in MANO's canonical frame, None when the frame test is unclear.

    In that frame a right hand's fingers run from the wrist toward -X and MANO_LEFT is its x-mirror, so the sign of
    the x component of (mean of joints 1..15 - wrist) decides. It is decisive only when that component carries at
    least half the length of the vector; a model in another frame (e.g. rotated by a user) gives None.
    """
    d = joints[1:].mean(0) - joints[0]
    if abs(d[0]) < 0.5 * np.linalg.norm(d):
        return None
    return "right" if d[0] < 0 else "left"


def side_from_name(path: str | Path) -> str | None:
    """'left'/'right' when the file name says so (MANO_LEFT.pkl, mano_right.pkl), else None."""
    stem = Path(path).stem.lower()
    has_left, has_right = "left" in stem, "right" in stem
    return "left" if has_left and not has_right else "right" if has_right and not has_left else None


def shapedirs_x_sign_wrong(v_template: np.ndarray, shapedirs: np.ndarray) -> bool | None:
    """Whether the x components of the shape directions have the wrong sign (MANO_LEFT's known bug).

    MANO_LEFT was made by mirroring MANO_RIGHT's vertices in x, but its shapedirs[:, 0, :] were not negated with
    them (smplx issue #48; the community fix is ``shapedirs[:, 0, :] *= -1`` for the left hand). The test is
    self-contained: MANO's first shape direction mostly changes hand size, i.e. shapedirs[:, :, 0] ~ s (v - c).
    So per axis d the Pearson correlation between shapedirs[:, d, 0] and v_template[:, d] has the sign of s on
    every axis of a correct model, while the buggy left model's x axis has the opposite sign to y and z.

    Returns True (x disagrees with y/z), False (they agree) or None when it cannot tell: no shape directions, or
    the x correlation or both y and z correlations weaker than 0.5, or y and z disagreeing. Limits: it relies on
    beta 0 being size-like, which holds for MANO's published models but not for arbitrary shape spaces (e.g. the
    random ones of synthetic test models).
    """
    if shapedirs.shape[2] == 0:
        return None
    corr = [_correlation(shapedirs[:, d, 0], v_template[:, d]) for d in range(3)]
    strong = [c for c in corr[1:] if abs(c) >= _DECISIVE_CORRELATION]
    if abs(corr[0]) < _DECISIVE_CORRELATION or not strong or len({np.sign(c) for c in strong}) > 1:
        return None
    return bool(np.sign(corr[0]) != np.sign(strong[0]))


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a - a.mean(), b - b.mean()
    denom = np.sqrt((a * a).sum() * (b * b).sum())
    return float((a * b).sum() / denom) if denom > 0 else 0.0


def fix_left_shapedirs(v_template: np.ndarray, shapedirs: np.ndarray, side: str) -> tuple[np.ndarray, list, str]:
    """(shapedirs, fixes applied, what the check found) after MANO_LEFT's x-sign fix where it is needed.

    Left models: flipped when `shapedirs_x_sign_wrong` says True, kept when it says False, and flipped when it
    cannot tell -- the official MANO_LEFT.pkl has the bug, so that is the community default. Right models are never
    changed (no such bug is known); a disagreeing right model is only reported in the returned note.
    """
    verdict = shapedirs_x_sign_wrong(v_template, shapedirs)
    if side == "right":
        note = "x sign disagrees with y/z (right model, left unchanged)" if verdict else "no fix for right models"
        return shapedirs, [], note
    if verdict is False:
        return shapedirs, [], "left model already has consistent x signs; not flipped"
    fixed = shapedirs.copy()
    fixed[:, 0, :] *= -1
    note = ("x sign disagreed with y/z (size direction test)" if verdict
            else "size direction test inconclusive; assumed the official MANO_LEFT bug")
    return fixed, [LEFT_SHAPEDIRS_FIX], note


def fallback_tip_ids(v_template: np.ndarray, weights: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(5,) fingertip vertices (thumb, index, middle, ring, pinky) for a mesh that is not MANO's 778-vertex one.

    Per finger: among the vertices whose largest skinning weight belongs to that finger's joint chain, the one
    farthest from the wrist joint. A finger that dominates no vertex gets the vertex nearest to its extrapolated
    tip (distal joint + last bone vector). Never fails; on odd meshes the result may be a poor tip.
    """
    dominant = weights.argmax(1)
    dist = np.linalg.norm(v_template - joints[0], axis=1)
    tips = []
    for finger in FINGERS:
        chain = FINGER_JOINTS[finger]
        members = np.flatnonzero(np.isin(dominant, chain))
        if members.size:
            tips.append(members[np.argmax(dist[members])])
        else:
            tip = 2 * joints[chain[-1]] - joints[chain[-2]]
            tips.append(np.argmin(np.linalg.norm(v_template - tip, axis=1)))
    return np.array(tips, dtype=np.int64)


# --------------------------------------------------------------------------------------------------------------------


def load_mano_pkl(path: str | Path) -> HandModel:
    """Load an official MANO pickle (or one re-saved by numpy/scipy without chumpy) as a checked `HandModel`.

    side: from the geometry (`side_from_joints`), else from the file name, else 'right'; a file name that
    contradicts the geometry is reported in meta['warnings'].
    tip_ids: `layout.MANO_TIP_IDS` for MANO's 778-vertex mesh, else `fallback_tip_ids`.
    shapedirs: MANO_LEFT's x-sign bug fixed per `fix_left_shapedirs`; meta['fixes'] lists what was applied.
    meta: source, format, sha256 (of the file's bytes), fixes, side_from, tip_ids_from, shapedirs_check,
    warnings.

    Raises UnsafePickleError if the file references a global outside `ALLOWED_GLOBALS` (nothing is executed),
    InputError naming the file (and field) for a missing, corrupt or inconsistent file.
    """
    path = Path(path)
    raw, sha256 = read_pickle(path, ALLOWED_GLOBALS, MANO_FORMAT)
    if not isinstance(raw, dict):
        raise InputError(f"{path}: not a MANO model: the pickle holds a {type(raw).__name__}, expected a dict")
    raw = {k.decode("latin1") if isinstance(k, bytes) else k: v for k, v in raw.items()}
    for key in _REQUIRED:
        if key not in raw:
            raise InputError(f"{path}: field '{key}' is missing")
    _check_text_fields(raw, path)

    v_template = _check_array(_field_array(raw, "v_template", path), "v_template", None, path)
    V = v_template.shape[0]
    arrays = {key: _check_array(_field_array(raw, key, path), key, V, path) for key in _FIELDS if key != "v_template"}
    faces = arrays["f"]
    if faces.size and (faces.min() < 0 or faces.max() >= V):
        bad = int(faces.max() if faces.max() >= V else faces.min())
        raise InputError(f"{path}: field 'f' indexes vertex {bad}, outside 0..{V - 1}")
    regressor = _regressor(raw, V, path)
    parents = parents_from_kintree(arrays["kintree_table"], path)

    warnings = []
    joints = regressor @ v_template
    geometric, named = side_from_joints(joints), side_from_name(path)
    side = geometric or named or "right"
    side_from = "geometry" if geometric else "file name" if named else "default"
    if geometric and named and geometric != named:
        warnings.append(f"file name says {named} but the geometry is a {geometric} hand; loaded as {geometric}")

    shapedirs, fixes, shapedirs_check = fix_left_shapedirs(v_template, arrays["shapedirs"], side)
    if V == MANO_NUM_VERTICES:
        tip_ids, tips_from = MANO_TIP_IDS.copy(), "MANO_TIP_IDS"
    else:
        tip_ids = fallback_tip_ids(v_template, arrays["weights"], joints)
        tips_from = "fallback: farthest-from-wrist vertex per finger chain"

    meta = {"source": str(path), "format": MANO_FORMAT, "sha256": sha256, "fixes": fixes, "side_from": side_from,
            "tip_ids_from": tips_from, "shapedirs_check": shapedirs_check, "warnings": warnings}
    return HandModel.create(
        source=str(path),
        v_template=v_template,
        faces=faces,
        weights=arrays["weights"],
        posedirs=arrays["posedirs"],
        J_regressor=regressor,
        parents=parents,
        shapedirs=shapedirs,
        hands_mean=arrays["hands_mean"],
        hands_components=arrays["hands_components"],
        tip_ids=tip_ids,
        side=side,
        meta=meta,
    )
