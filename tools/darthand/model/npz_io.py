"""darthand's own model format: a compressed `.npz` (schema: schemas/model_npz.schema.json).

Loss-free: every array is stored at float64/int64 as held in memory, the sparse regressor as CSR parts, and the
file is read with `allow_pickle=False`, so loading never executes code.
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from darthand.errors import InputError
from darthand.fileio import atomic_path
from darthand.model.hand_model import HandModel

FORMAT = "darthand-model"
FORMAT_VERSION = 1
_DENSE = ("v_template", "faces", "weights", "posedirs", "parents", "shapedirs", "hands_mean", "hands_components",
          "tip_ids")
_OPTIONAL = ("uvs", "faces_uv", "face_labels")
_REGRESSOR = ("J_regressor_data", "J_regressor_indices", "J_regressor_indptr", "J_regressor_shape")


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
    """Read a model written by `save_npz`; raise InputError naming the file and field on any problem."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such model file")
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as e:
        raise InputError(f"{path}: not a readable darthand model .npz ({_first_line(e)})") from None
    if str(data.get("format", "")) != FORMAT:
        raise InputError(f"{path}: field 'format' missing or not '{FORMAT}': not a darthand model file")
    if int(data["format_version"]) > FORMAT_VERSION:
        raise InputError(f"{path}: field 'format_version' is {int(data['format_version'])}, "
                         f"this darthand reads up to {FORMAT_VERSION}")
    for key in _DENSE + _REGRESSOR + ("side",):
        if key not in data:
            raise InputError(f"{path}: field '{key}' is missing")
    try:
        regressor = sp.csr_matrix((data["J_regressor_data"], data["J_regressor_indices"], data["J_regressor_indptr"]),
                                  shape=tuple(int(s) for s in data["J_regressor_shape"]))
    except (ValueError, TypeError) as e:
        raise InputError(f"{path}: field 'J_regressor' is not a valid CSR matrix ({_first_line(e)})") from None
    try:
        meta = json.loads(str(data["meta_json"])) if "meta_json" in data else {}
    except json.JSONDecodeError:
        raise InputError(f"{path}: field 'meta_json' is not valid JSON") from None
    fields = {name: data[name] for name in _DENSE}
    fields.update({name: data.get(name) for name in _OPTIONAL})
    meta.setdefault("source", str(path))
    return HandModel.create(source=str(path), J_regressor=regressor, side=str(data["side"]), meta=meta, **fields)


def _first_line(e: BaseException) -> str:
    return (str(e).splitlines() or [type(e).__name__])[0]
