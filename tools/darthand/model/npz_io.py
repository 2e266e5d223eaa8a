"""darthand's own model format: a compressed `.npz` (schema: schemas/model_npz.schema.json).

Loss-free: every array is stored at float64/int64 as held in memory, the sparse regressor as CSR parts, and the
file is read with `allow_pickle=False`, so loading never executes code; everything a file declares is checked
before it is used (`load_npz`).
"""

from __future__ import annotations

import io
import json
import math
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from darthand.budget import check_memory
from darthand.errors import InputError
from darthand.fileio import atomic_path, open_regular, parse_json
from darthand.model.hand_model import HandModel
from darthand.model.layout import NUM_JOINTS
from darthand.schemas import check_schema, load_schema

FORMAT = "darthand-model"
FORMAT_VERSION = 1
_DENSE = ("v_template", "faces", "weights", "posedirs", "parents", "shapedirs", "hands_mean", "hands_components",
          "tip_ids")
_OPTIONAL = ("uvs", "faces_uv", "face_labels")
_REGRESSOR = ("J_regressor_data", "J_regressor_indices", "J_regressor_indptr", "J_regressor_shape")
_HEADER_READERS = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}


def save_npz(model: HandModel, path: str | Path) -> None:
    """Write `model` to `path` atomically."""
    arrays = {name: getattr(model, name) for name in _DENSE}
    arrays.update({name: getattr(model, name) for name in _OPTIONAL if getattr(model, name) is not None})
    reg = model.J_regressor.tocsr()
    reg.sort_indices()
    arrays.update(J_regressor_data=reg.data, J_regressor_indices=reg.indices.astype(np.int64),
                  J_regressor_indptr=reg.indptr.astype(np.int64), J_regressor_shape=np.array(reg.shape, np.int64))
    arrays["side"] = np.array(model.side)
    arrays["format"] = np.array(FORMAT)
    arrays["format_version"] = np.array(FORMAT_VERSION, dtype=np.int64)
    arrays["meta_json"] = np.array(json.dumps(model.meta, sort_keys=True))
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.getvalue())


def load_npz(path: str | Path) -> HandModel:
    """Read a model written by `save_npz`; raise InputError naming the file and field on any problem.

    Untrusted files are read in this order, so nothing is allocated or indexed before it is known to be sound:
    the members' declared dtypes and shapes against schemas/model_npz.schema.json and against each other, their
    total size against the memory budget and against the bytes the zip really holds; then the arrays; then the
    sparse regressor's parts (index bounds, indptr order) before scipy sees them; then every field (`check_model`).
    """
    path = Path(path)
    with open_regular(path, "model file") as f:
        try:
            with zipfile.ZipFile(f) as z:
                members = member_headers(z, path)
                check_declared(members, path)
                data = {name: read_member(z, info, path) for name, info in members.items()}
        except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, OSError) as e:
            raise InputError(f"{path}: not a readable darthand model .npz ({_first_line(e)})") from None
    if str(data["format"]) != FORMAT:
        raise InputError(f"{path}: field 'format' is not '{FORMAT}': not a darthand model file")
    version = int(data["format_version"])
    if not 1 <= version <= FORMAT_VERSION:
        raise InputError(f"{path}: field 'format_version' is {version}, this darthand reads 1..{FORMAT_VERSION}")
    regressor = checked_regressor(data, int(members["v_template"].shape[0]), path)
    meta = parse_json(str(data["meta_json"]), f"{path}: field 'meta_json'", "model's metadata") \
        if "meta_json" in data else {}
    if not isinstance(meta, dict):
        raise InputError(f"{path}: field 'meta_json' holds a {type(meta).__name__}, expected a JSON object")
    fields: dict[str, np.ndarray | None] = {name: data[name] for name in _DENSE}
    fields.update({name: data.get(name) for name in _OPTIONAL})
    meta.setdefault("source", str(path))
    return HandModel.create(source=str(path), J_regressor=regressor, side=str(data["side"]), meta=meta, **fields)


@dataclass(frozen=True)
class Member:
    """One .npy member of the zip as its header declares it."""

    info: zipfile.ZipInfo
    dtype: np.dtype
    shape: tuple
    offset: int           # bytes of magic and header before the data

    @property
    def nbytes(self) -> int:
        return math.prod(self.shape) * self.dtype.itemsize


def member_headers(z: zipfile.ZipFile, path: Path) -> dict[str, Member]:
    """{field: Member} from each member's .npy header (a few hundred bytes read per member, no data)."""
    members = {}
    infos = z.infolist()
    if len(infos) > 64:
        raise InputError(f"{path}: holds {len(infos)} members, not a darthand model file")
    for info in infos:
        name = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
        try:
            with z.open(info) as f:
                version = np.lib.format.read_magic(f)
                if version not in _HEADER_READERS:
                    raise ValueError(f".npy format version {version[0]}.{version[1]} (1.0 and 2.0 are read)")
                shape, fortran, dtype = _HEADER_READERS[version](f, max_header_size=4096)
                offset = f.tell()
        except (ValueError, SyntaxError, TypeError, OverflowError, RecursionError, MemoryError) as e:
            raise InputError(f"{path}: field '{ascii(name)[1:-1][:80]}' is not a readable .npy array "
                             f"({_first_line(e)})") from None
        members[name] = Member(info, dtype, tuple(int(n) for n in shape), offset)
    return members


def check_declared(members: dict[str, Member], path: Path) -> None:
    """Dtypes and shapes against the file contract and against each other, sizes against the budget and the zip,
    before any array is read."""
    description = {name: {"dtype": m.dtype.str[1:], "shape": list(m.shape)} for name, m in members.items()}
    for name, m in members.items():
        if m.dtype.hasobject or m.dtype.names is not None:
            raise InputError(f"{path}: field '{ascii(name)[1:-1][:80]}' has dtype {m.dtype.str}, which this "
                             "loader does not read (object or structured arrays)")
    if "format" not in members or description["format"]["dtype"][:1] != "U":
        raise InputError(f"{path}: field 'format' missing or not '{FORMAT}': not a darthand model file")
    contract = load_schema("model_npz.schema.json")["properties"]
    for name, d in description.items():
        if name in contract:
            _check_member(name, d, contract[name], path)
    check_schema(description, "model_npz.schema.json", str(path))
    V = members["v_template"].shape[0]
    for name in ("weights", "posedirs", "shapedirs"):
        if members[name].shape[0] != V:
            raise InputError(f"{path}: field '{name}' has {members[name].shape[0]} rows for {V} vertices")
    check_memory(f"loading the model {path}", 2 * sum(m.nbytes for m in members.values()))
    for name, m in members.items():
        if m.info.file_size < m.offset + m.nbytes:
            raise InputError(f"{path}: field '{name}' declares {m.nbytes} bytes of data but the file holds "
                             f"{max(m.info.file_size - m.offset, 0)}: truncated or corrupt")


def _check_member(name: str, declared: dict, contract: dict, path: Path) -> None:
    """A member's declared dtype and shape against its schema entry, in the words of `check_model`."""
    dtype, shape = contract["properties"]["dtype"], contract["properties"]["shape"]
    if declared["dtype"] not in dtype.get("enum", [declared["dtype"]]) or \
            not re.fullmatch(dtype.get("pattern", ".*"), declared["dtype"]):
        want = "/".join(dtype["enum"]) if "enum" in dtype else "a string"
        raise InputError(f"{path}: field '{name}' has dtype {declared['dtype']}, expected {want}")
    items = shape.get("prefixItems")
    if items is None:
        return
    want = [str(i["const"]) if "const" in i else "?" for i in items]
    got = declared["shape"]
    if len(got) != len(items) or any(w != "?" and str(n) != w for n, w in zip(got, want)):
        raise InputError(f"{path}: field '{name}' has shape {'x'.join(map(str, got)) or '()'}, expected "
                         f"{'x'.join(want)}")


def read_member(z: zipfile.ZipFile, m: Member, path: Path) -> np.ndarray:
    try:
        with z.open(m.info) as f:
            return np.lib.format.read_array(f, allow_pickle=False, max_header_size=4096)
    except (ValueError, EOFError) as e:
        raise InputError(f"{path}: field '{m.info.filename[:-4]}' cannot be read ({_first_line(e)})") from None


def checked_regressor(data: dict, V: int, path: Path) -> sp.csr_matrix:
    """The CSR regressor from its parts, after checking every index against the shape (scipy does not, and an
    index past the vertices makes the matrix products read outside their arrays)."""
    rows, cols = (int(n) for n in data["J_regressor_shape"])
    values, indices, indptr = (data[f"J_regressor_{k}"] for k in ("data", "indices", "indptr"))

    def fail(field: str, msg: str):
        raise InputError(f"{path}: field 'J_regressor_{field}' {msg}")

    if (rows, cols) != (NUM_JOINTS, V):
        fail("shape", f"is {rows}x{cols}, expected {NUM_JOINTS}x{V} (joints x vertices)")
    if len(indptr) != rows + 1 or indptr[0] != 0 or (np.diff(indptr) < 0).any():
        fail("indptr", f"is not {rows + 1} non-decreasing offsets from 0")
    if indptr[-1] != len(indices) or len(indices) != len(values):
        fail("indptr", f"ends at {int(indptr[-1])} for {len(indices)} indices and {len(values)} values")
    if len(indices) and (indices.min() < 0 or indices.max() >= cols):
        bad = int(indices.max() if indices.max() >= cols else indices.min())
        fail("indices", f"holds column {bad}, outside 0..{cols - 1}")
    return sp.csr_matrix((values, indices, indptr), shape=(rows, cols))


def _first_line(e: BaseException) -> str:
    return (str(e).splitlines() or [type(e).__name__])[0][:200]
