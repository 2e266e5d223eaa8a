"""darthand's model format: loss-free round trip, schema, and clear errors on bad files."""

import json
import zipfile
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from darthand.errors import InputError
from darthand.model.npz_io import load_npz, save_npz
from darthand.model.wrist import add_wrist
from synthetic import tube_hand

SCHEMA = Path(__file__).resolve().parents[2] / "schemas" / "model_npz.schema.json"
FIELDS = ("v_template", "faces", "weights", "posedirs", "parents", "shapedirs", "hands_mean", "hands_components",
          "tip_ids", "uvs", "faces_uv", "face_labels")


@pytest.fixture(scope="module")
def model():
    return add_wrist(tube_hand(seed=11))


def test_round_trip_is_loss_free(model, tmp_path):
    save_npz(model, tmp_path / "m.npz")
    back = load_npz(tmp_path / "m.npz")
    for name in FIELDS:
        a, b = getattr(model, name), getattr(back, name)
        assert a.dtype == b.dtype, name
        np.testing.assert_array_equal(a, b, err_msg=name)
    assert (model.J_regressor != back.J_regressor).nnz == 0
    assert back.side == model.side
    assert back.meta["wrist"] == model.meta["wrist"]


def test_file_matches_schema(model, tmp_path):
    save_npz(model, tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz") as z:
        description = {k: {"dtype": z[k].dtype.str[1:], "shape": list(z[k].shape)} for k in z.files}
    jsonschema.validate(description, json.loads(SCHEMA.read_text()))


def test_no_temporary_left_behind(model, tmp_path):
    save_npz(model, tmp_path / "m.npz")
    assert [p.name for p in tmp_path.iterdir()] == ["m.npz"]


def _write(path, **arrays):
    np.savez(path, **arrays)
    return path


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="no such model file"):
        load_npz(tmp_path / "absent.npz")


def test_truncated_file(model, tmp_path):
    save_npz(model, tmp_path / "m.npz")
    data = (tmp_path / "m.npz").read_bytes()
    (tmp_path / "t.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="t.npz: not a readable"):
        load_npz(tmp_path / "t.npz")


def test_not_our_format(tmp_path):
    with pytest.raises(InputError, match="format"):
        load_npz(_write(tmp_path / "x.npz", a=np.zeros(3)))


def test_pickled_object_array_is_refused(model, tmp_path):
    save_npz(model, tmp_path / "m.npz")
    with zipfile.ZipFile(tmp_path / "m.npz") as z:
        members = {n: z.read(n) for n in z.namelist()}
    with zipfile.ZipFile(tmp_path / "evil.npz", "w") as z:
        for name, data in members.items():
            if name != "hands_mean.npy":
                z.writestr(name, data)
        import io
        buf = io.BytesIO()
        np.save(buf, np.array([{"x": 1}], dtype=object), allow_pickle=True)
        z.writestr("hands_mean.npy", buf.getvalue())
    with pytest.raises(InputError, match="evil.npz"):
        load_npz(tmp_path / "evil.npz")


@pytest.mark.parametrize("field, value, message", [
    ("weights", lambda m: m.weights[:, :15], "'weights' has shape"),
    ("v_template", lambda m: np.where(np.arange(len(m.v_template))[:, None] == 5, np.nan, m.v_template),
     r"'v_template' has a non-finite value \(nan\) at index \(5, 0\)"),
    ("parents", lambda m: np.array([-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 15, 14]), "not a tree"),
    ("parents", lambda m: np.array([0, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14]), "joint 0"),
    ("faces", lambda m: m.faces + 10 ** 6, "'faces' indexes vertex"),
    ("weights", lambda m: -m.weights, "negative weight"),
])
def test_bad_fields_are_named(model, tmp_path, field, value, message):
    save_npz(model, tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays[field] = value(model)
    with pytest.raises(InputError, match=message):
        load_npz(_write(tmp_path / "bad.npz", **arrays))
