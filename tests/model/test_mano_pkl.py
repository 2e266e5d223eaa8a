"""The MANO pickle loader: exact round trips, the MANO_LEFT fix, refusal of unsafe pickles, clean errors."""

from __future__ import annotations

import hashlib
import json
import pickle
import pickletools
import struct
import sys
import time

import numpy as np
import pytest
import scipy.sparse as sp

from darthand.errors import InputError, UnsafePickleError
from darthand.model.layout import FINGER_JOINTS, FINGERS, MANO_PARENTS, MANO_TIP_IDS
from darthand.model.mano_pkl import (
    ALLOWED_GLOBALS,
    LEFT_SHAPEDIRS_FIX,
    MANO_FORMAT,
    evaluate,
    is_mano_pkl,
    load_mano_pkl,
    shapedirs_x_sign_wrong,
)
from darthand.model.npz_io import load_npz, save_npz
from darthand.safe_pickle import read_pickle
from model.mano_fixture import (
    MALICIOUS_KINDS,
    add_vertices,
    dumps_like_mano,
    malicious_pickle,
    mirror_x,
    with_size_direction,
    write_mano_pkl,
    write_nested_malicious,
)
from synthetic import tube_hand


def assert_same_rig(loaded, expected):
    """Every field a MANO pickle carries, bit for bit."""
    for name in ("v_template", "faces", "weights", "posedirs", "shapedirs", "hands_mean", "hands_components"):
        a, b = getattr(loaded, name), getattr(expected, name)
        assert a.dtype == b.dtype and a.shape == b.shape, name
        assert np.array_equal(a, b), name
    assert isinstance(loaded.J_regressor, sp.csr_matrix)
    assert np.array_equal(loaded.J_regressor.toarray(), expected.J_regressor.toarray())
    assert np.array_equal(loaded.parents, MANO_PARENTS)
    assert loaded.side == expected.side
    assert loaded.uvs is None and loaded.faces_uv is None and loaded.face_labels is None


def globals_in(data: bytes) -> set[str]:
    found, strings = set(), []
    for op, arg, _ in pickletools.genops(data):
        if op.name == "GLOBAL":
            found.add(arg.replace(" ", "."))
        elif op.name == "STACK_GLOBAL":
            found.add(".".join(strings[-2:]))
        if isinstance(arg, str):
            strings.append(arg)
    return found


def one_line_naming(err: Exception, path, *words: str) -> str:
    msg = str(err)
    assert "\n" not in msg
    assert str(path) in msg
    for word in words:
        assert word in msg, (word, msg)
    return msg


# --------------------------------------------------------------------------------------------------------------------
# The fixture itself looks like the official files.


def test_fixture_pickle_references_the_official_globals(tmp_path):
    path = write_mano_pkl(tmp_path / "MANO_RIGHT.pkl", shapedirs_as="select")
    data = path.read_bytes()
    assert data[:2] == b"\x80\x02"
    assert globals_in(data) == {"numpy.core.multiarray._reconstruct", "numpy.ndarray", "numpy.dtype",
                                "scipy.sparse.csc.csc_matrix", "chumpy.ch.Ch", "chumpy.reordering.Select",
                                "__builtin__.set"}
    assert not any(name == "chumpy" or name.startswith("chumpy.") for name in sys.modules)
    with pytest.raises(ModuleNotFoundError):  # chumpy is not importable here: a plain load cannot even resolve Ch
        pickle.loads(data, encoding="latin1")


def test_every_allowed_global_is_a_known_pair():
    modules = {m for m, _ in ALLOWED_GLOBALS}
    assert modules <= {"numpy.core.multiarray", "numpy._core.multiarray", "numpy.core.numeric", "numpy._core.numeric",
                       "numpy", "scipy.sparse.csc", "scipy.sparse._csc", "scipy.sparse.csr", "scipy.sparse._csr",
                       "chumpy.ch", "chumpy.reordering", "__builtin__", "builtins", "copy_reg", "copyreg", "_codecs"}
    assert ("os", "system") not in ALLOWED_GLOBALS and ("builtins", "eval") not in ALLOWED_GLOBALS


# --------------------------------------------------------------------------------------------------------------------
# Round trips.


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("shapedirs_as", ["ch", "select", "array"])
def test_round_trip_every_field(tmp_path, side, shapedirs_as):
    source = tube_hand(seed=3)
    path = write_mano_pkl(tmp_path / f"MANO_{side.upper()}.pkl", source, side=side, shapedirs_as=shapedirs_as)
    loaded = load_mano_pkl(path)
    expected = source if side == "right" else mirror_x(source)
    assert_same_rig(loaded, expected)
    assert loaded.meta["source"] == str(path)
    assert loaded.meta["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    json.dumps(loaded.meta)  # the npz writer stores meta as JSON


@pytest.mark.parametrize("protocol,py2", [(0, False), (1, True), (2, False), (4, False), (5, False)])
def test_round_trip_other_pickle_flavours(tmp_path, protocol, py2):
    """Protocol 0 (copy_reg._reconstructor, _codecs.encode), Python 3 protocol 2, and numpy 2 protocol 5 re-saves."""
    source = tube_hand(seed=4)
    path = write_mano_pkl(tmp_path / "hand.pkl", source, protocol=protocol, py2=py2,
                          ch_fields=("v_template", "weights", "posedirs", "J"))
    assert_same_rig(load_mano_pkl(path), source)


def test_protocol_0_uses_the_reconstructor_path(tmp_path):
    path = write_mano_pkl(tmp_path / "hand.pkl", protocol=0, py2=False)
    assert {"copy_reg._reconstructor", "__builtin__.object", "_codecs.encode"} <= globals_in(path.read_bytes())


def test_loaded_model_survives_the_npz_format(tmp_path):
    path = write_mano_pkl(tmp_path / "MANO_LEFT.pkl", side="left")
    loaded = load_mano_pkl(path)
    save_npz(loaded, tmp_path / "left.npz")
    again = load_npz(tmp_path / "left.npz")
    assert_same_rig(again, loaded)
    assert again.meta["fixes"] == loaded.meta["fixes"] == [LEFT_SHAPEDIRS_FIX]


# --------------------------------------------------------------------------------------------------------------------
# Fingertips.


def pad_to(model, n_vertices):
    extra = n_vertices - model.num_vertices
    points = np.tile(model.v_template[:1], (extra, 1))
    return add_vertices(model, points, np.tile(model.weights[:1], (extra, 1)))


def test_778_vertex_model_gets_manos_tip_ids(tmp_path):
    source = pad_to(tube_hand(), 778)
    loaded = load_mano_pkl(write_mano_pkl(tmp_path / "MANO_RIGHT.pkl", source))
    assert np.array_equal(loaded.tip_ids, [745, 317, 444, 556, 673])
    assert np.array_equal(loaded.tip_ids, MANO_TIP_IDS)


def test_fallback_tips_are_the_outermost_vertex_of_each_finger(tmp_path):
    """Five vertices placed 8 cm beyond each distal joint, fully bound to it, are each finger's farthest vertex."""
    source = tube_hand()
    joints = source.J_regressor @ source.v_template
    distal = [FINGER_JOINTS[f][-1] for f in FINGERS]
    points = joints[distal] + [-0.08, 0.0, 0.0]
    weights = np.zeros((5, 16))
    weights[np.arange(5), distal] = 1.0
    model = add_vertices(source, points, weights)
    loaded = load_mano_pkl(write_mano_pkl(tmp_path / "hand.pkl", model))
    V = source.num_vertices
    assert np.array_equal(loaded.tip_ids, [V, V + 1, V + 2, V + 3, V + 4])
    assert loaded.meta["tip_ids_from"].startswith("fallback")


# --------------------------------------------------------------------------------------------------------------------
# Side and the MANO_LEFT shapedirs bug.


def test_left_bug_detected_and_fixed(tmp_path):
    source = with_size_direction(tube_hand(seed=5))
    path = write_mano_pkl(tmp_path / "MANO_LEFT.pkl", source, side="left", left_bug=True)
    expected = mirror_x(source)
    in_file = evaluate(read_pickle(path, ALLOWED_GLOBALS, MANO_FORMAT)[0]["shapedirs"])
    assert np.array_equal(in_file[:, 0], -expected.shapedirs[:, 0])  # the file has the bug ...
    assert np.array_equal(in_file[:, 1:], expected.shapedirs[:, 1:])
    loaded = load_mano_pkl(path)
    assert loaded.meta["fixes"] == [LEFT_SHAPEDIRS_FIX]
    assert "disagreed" in loaded.meta["shapedirs_check"]
    assert_same_rig(loaded, expected)  # ... and the loaded model does not


def test_left_fix_not_applied_to_an_already_fixed_file(tmp_path):
    source = with_size_direction(tube_hand(seed=5))
    path = write_mano_pkl(tmp_path / "MANO_LEFT.pkl", source, side="left", left_bug=False)
    loaded = load_mano_pkl(path)
    assert loaded.meta["fixes"] == []
    assert_same_rig(loaded, mirror_x(source))
    assert_same_rig(load_mano_pkl(path), mirror_x(source))  # loading again changes nothing


def test_right_file_is_never_flipped(tmp_path):
    source = with_size_direction(tube_hand(seed=6))
    loaded = load_mano_pkl(write_mano_pkl(tmp_path / "MANO_RIGHT.pkl", source))
    assert loaded.meta["fixes"] == []
    assert_same_rig(loaded, source)


def test_left_file_with_an_inconclusive_test_assumes_the_official_bug(tmp_path):
    source = tube_hand(seed=7)  # random shape directions: no size-like beta 0
    assert shapedirs_x_sign_wrong(mirror_x(source).v_template, mirror_x(source).shapedirs) is None
    loaded = load_mano_pkl(write_mano_pkl(tmp_path / "MANO_LEFT.pkl", source, side="left", left_bug=True))
    assert loaded.meta["fixes"] == [LEFT_SHAPEDIRS_FIX]
    assert "assumed" in loaded.meta["shapedirs_check"]
    assert_same_rig(loaded, mirror_x(source))


@pytest.mark.parametrize("scale", [0.07, -0.04])
def test_shapedirs_sign_test_closed_form(scale):
    rng = np.random.default_rng(1)
    v = rng.normal(size=(300, 3)) * [0.08, 0.01, 0.04]
    shapedirs = np.zeros((300, 3, 3))
    shapedirs[:, :, 0] = scale * (v - [0.05, 0.0, 0.01]) + 1e-4 * rng.normal(size=(300, 3))
    shapedirs[:, :, 1:] = rng.normal(size=(300, 3, 2))
    assert shapedirs_x_sign_wrong(v, shapedirs) is False
    bad = shapedirs.copy()
    bad[:, 0, :] *= -1
    assert shapedirs_x_sign_wrong(v, bad) is True
    noise = rng.normal(size=(300, 3, 3))
    assert shapedirs_x_sign_wrong(v, noise) is None
    assert shapedirs_x_sign_wrong(v, np.zeros((300, 3, 0))) is None


def test_side_from_geometry_overrides_a_contradicting_file_name(tmp_path):
    loaded = load_mano_pkl(write_mano_pkl(tmp_path / "MANO_LEFT.pkl", side="right"))
    assert loaded.side == "right"
    assert loaded.meta["side_from"] == "geometry"
    assert any("file name says left" in w for w in loaded.meta["warnings"])
    assert loaded.meta["fixes"] == []


def rotated_about_y(model):
    """Fingers along -Z instead of -X: outside the frame the geometric side test understands."""
    rot = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # (x, y, z) -> (-z, y, x)
    return model.replace(v_template=model.v_template @ rot.T)


@pytest.mark.parametrize("name,side,side_from", [("my_left_hand.pkl", "left", "file name"),
                                                  ("hand.pkl", "right", "default")])
def test_side_falls_back_to_the_file_name(tmp_path, name, side, side_from):
    model = rotated_about_y(tube_hand())
    joints = model.J_regressor @ model.v_template
    assert abs((joints[1:].mean(0) - joints[0])[0]) < 1e-9 + 0.1 * np.linalg.norm(joints[1:].mean(0) - joints[0])
    loaded = load_mano_pkl(write_mano_pkl(tmp_path / name, model, side="right"))
    assert (loaded.side, loaded.meta["side_from"]) == (side, side_from)


# --------------------------------------------------------------------------------------------------------------------
# Unsafe pickles: refused, nothing executed.


def wait_for(path, seconds=1.0):
    end = time.monotonic() + seconds
    while time.monotonic() < end and not path.exists():
        time.sleep(0.05)
    return path.exists()


@pytest.mark.parametrize("kind", MALICIOUS_KINDS)
def test_malicious_payloads_are_live_under_plain_pickle(tmp_path, kind):
    """Control: the payloads really do run under pickle.loads, so the refusal tests below can fail."""
    marker = tmp_path / "pwned"
    result = pickle.loads(malicious_pickle(kind, marker), encoding="latin1")
    if hasattr(result, "wait"):
        result.wait()
    assert wait_for(marker)


@pytest.mark.parametrize("kind", MALICIOUS_KINDS)
def test_malicious_globals_are_refused_and_nothing_runs(tmp_path, kind):
    marker = tmp_path / "pwned"
    path = tmp_path / "MANO_RIGHT.pkl"
    path.write_bytes(malicious_pickle(kind, marker))
    with pytest.raises(UnsafePickleError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, f"'{kind}'", "refused global")
    assert not wait_for(marker, 0.3 if kind == "subprocess.Popen" else 0.0)


def test_nested_reduce_inside_the_dict_is_refused(tmp_path):
    marker = tmp_path / "pwned"
    path = write_nested_malicious(tmp_path / "MANO_RIGHT.pkl", marker)
    assert "posix.system" in globals_in(path.read_bytes())
    with pytest.raises(UnsafePickleError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, "'posix.system'")
    assert not marker.exists()


def _g(module, name):
    return pickle.GLOBAL + f"{module}\n{name}\n".encode()


def _int(n):
    return pickle.BININT1 + bytes([n])


def _call(func, *args):
    return func + pickle.MARK + b"".join(args) + pickle.TUPLE + pickle.REDUCE


def _proto2(body):
    return b"\x80\x02" + body + pickle.STOP


def _short_str(s):
    return pickle.SHORT_BINSTRING + bytes([len(s)]) + s.encode()


REFUSED_CALLS = {
    "ndarray called": (_call(_g("numpy", "ndarray"), pickle.MARK + _int(3) + pickle.TUPLE), "numpy.ndarray"),
    "object called": (_call(_g("__builtin__", "object")), "builtins.object"),
    "reconstruct of object": (_call(_g("numpy.core.multiarray", "_reconstruct"), _g("__builtin__", "object"),
                                    pickle.MARK + _int(0) + pickle.TUPLE, _short_str("b")), "_reconstruct"),
    "reconstructor of ndarray": (_call(_g("copy_reg", "_reconstructor"), _g("numpy", "ndarray"),
                                       _g("__builtin__", "object"), pickle.NONE), "_reconstructor"),
    "Ch called directly": (_call(_g("chumpy.ch", "Ch"), _int(1)), "chumpy.ch.Ch"),
    "codecs other encoding": (_call(_g("_codecs", "encode"), _short_str("x"), _short_str("rot13")), "_codecs.encode"),
    "set of a string": (_call(_g("__builtin__", "set"), _short_str("abc")), "builtins.set"),
    "dtype of a list": (_call(_g("numpy", "dtype"), pickle.EMPTY_LIST), "numpy.dtype"),
    "BUILD on a guard": (_g("numpy", "dtype") + pickle.EMPTY_DICT + pickle.BUILD, "numpy.dtype"),
}


@pytest.mark.parametrize("case", sorted(REFUSED_CALLS))
def test_unexpected_calls_of_allowed_globals_are_refused(tmp_path, case):
    body, name = REFUSED_CALLS[case]
    path = tmp_path / "MANO_RIGHT.pkl"
    path.write_bytes(_proto2(body))
    with pytest.raises(UnsafePickleError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, "refused", name)


# --------------------------------------------------------------------------------------------------------------------
# Bad input: one-line InputErrors naming the file (and field).


def test_missing_file(tmp_path):
    with pytest.raises(InputError) as err:
        load_mano_pkl(tmp_path / "MANO_RIGHT.pkl")
    one_line_naming(err.value, tmp_path / "MANO_RIGHT.pkl", "no such file")


def test_not_a_pickle(tmp_path):
    path = tmp_path / "MANO_RIGHT.pkl"
    path.write_text("this is not a pickle\n")
    with pytest.raises(InputError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, "pickle")
    assert not isinstance(err.value, UnsafePickleError)


@pytest.mark.parametrize("fraction", [0.001, 0.3, 0.7, 0.9999])
def test_truncated_pickle(tmp_path, fraction):
    path = write_mano_pkl(tmp_path / "MANO_RIGHT.pkl")
    data = path.read_bytes()
    path.write_bytes(data[: max(1, int(len(data) * fraction))])
    with pytest.raises(InputError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path)


def test_not_a_dict(tmp_path):
    path = tmp_path / "MANO_RIGHT.pkl"
    path.write_bytes(pickle.dumps([1, 2, 3], protocol=2))
    with pytest.raises(InputError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, "expected a dict")


@pytest.mark.parametrize("field", ["v_template", "f", "posedirs", "shapedirs", "J_regressor", "kintree_table"])
def test_missing_field(tmp_path, field):
    path = write_mano_pkl(tmp_path / "MANO_RIGHT.pkl", drop=(field,))
    with pytest.raises(InputError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, f"'{field}'", "missing")


V_TUBE = tube_hand().num_vertices
BAD_SHAPES = {
    "posedirs": (np.zeros((V_TUBE, 3, 134)), f"{V_TUBE}x3x135"),
    "weights": (np.zeros((V_TUBE, 15)), f"{V_TUBE}x16"),
    "f": (np.zeros((10, 4), np.uint32), "?x3"),
    "v_template": (np.zeros((V_TUBE, 2)), "?x3"),
    "shapedirs": (np.zeros((V_TUBE - 1, 3, 4)), f"{V_TUBE}x3x?"),
    "hands_mean": (np.zeros(44), "45"),
    "kintree_table": (np.zeros((2, 15), np.uint32), "2x16"),
    "J_regressor": (sp.csc_matrix((15, V_TUBE)), f"16x{V_TUBE}"),
}


@pytest.mark.parametrize("field", sorted(BAD_SHAPES))
def test_wrong_shapes(tmp_path, field):
    value, expected = BAD_SHAPES[field]
    path = write_mano_pkl(tmp_path / "MANO_RIGHT.pkl", override={field: value})
    with pytest.raises(InputError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, f"'{field}'", f"expected {expected}")


def test_float_faces_are_refused(tmp_path):
    model = tube_hand()
    path = write_mano_pkl(tmp_path / "MANO_RIGHT.pkl", override={"f": model.faces.astype(np.float64)})
    with pytest.raises(InputError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, "'f'", "integer")


@pytest.mark.parametrize("field,ch", [("v_template", False), ("posedirs", True), ("hands_components", False)])
def test_nan_is_refused_with_its_index(tmp_path, field, ch):
    source = tube_hand()
    value = np.array(getattr(source, field))
    index = (3, 1) if value.ndim == 2 else (3, 1, 7)
    value[index] = np.nan
    path = write_mano_pkl(tmp_path / "MANO_RIGHT.pkl", override={field: value}, ch_fields=(field,) if ch else ())
    with pytest.raises(InputError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, f"'{field}'", "nan", str(index))


def test_nan_in_the_regressor(tmp_path):
    regressor = sp.csc_matrix(tube_hand().J_regressor)
    regressor.data[5] = np.inf
    path = write_mano_pkl(tmp_path / "MANO_RIGHT.pkl", override={"J_regressor": regressor})
    with pytest.raises(InputError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, "'J_regressor'", "inf")


def test_regressor_with_out_of_range_indices(tmp_path):
    regressor = sp.csc_matrix(tube_hand().J_regressor)
    regressor.indices[0] = 99
    path = write_mano_pkl(tmp_path / "MANO_RIGHT.pkl", override={"J_regressor": regressor})
    with pytest.raises(InputError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, "'J_regressor'")


def kintree(parents, ids=None):
    parents = np.where(np.asarray(parents) < 0, 4294967295, parents)
    return np.stack([parents, np.arange(16) if ids is None else ids]).astype(np.uint32)


BAD_TREES = {
    "child before parent": kintree([-1, 0, 1, 2, 0, 7, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14]),
    "two roots": kintree([-1, 0, 1, 2, -1, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14]),
    "self parent": kintree([-1, 1, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14]),
    "ids not a permutation": kintree(MANO_PARENTS, ids=[0] * 16),
}


@pytest.mark.parametrize("case", sorted(BAD_TREES))
def test_kintree_not_a_tree(tmp_path, case):
    path = write_mano_pkl(tmp_path / "MANO_RIGHT.pkl", override={"kintree_table": BAD_TREES[case]})
    with pytest.raises(InputError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, "kintree_table")


def test_kintree_in_another_column_order_gives_the_same_parents(tmp_path):
    order = np.random.default_rng(0).permutation(16)
    table = kintree(MANO_PARENTS)[:, order]
    loaded = load_mano_pkl(write_mano_pkl(tmp_path / "MANO_RIGHT.pkl", override={"kintree_table": table}))
    assert np.array_equal(loaded.parents, MANO_PARENTS)


def test_unsupported_blend_skinning(tmp_path):
    path = write_mano_pkl(tmp_path / "MANO_RIGHT.pkl", override={"bs_style": "dqs"})
    with pytest.raises(InputError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, "'bs_style'", "dqs")


def test_select_with_indices_outside_its_array(tmp_path):
    from model.mano_fixture import Ch, Select

    bad = Select(Ch(np.zeros(6)), [0, 1, 99], (3,))
    path = write_mano_pkl(tmp_path / "MANO_RIGHT.pkl", override={"shapedirs": bad})
    with pytest.raises(InputError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, "'shapedirs'")


def test_chumpy_cycle_is_an_input_error(tmp_path):
    from model.mano_fixture import Ch

    a = Ch(np.zeros(3))
    a.x = a
    path = write_mano_pkl(tmp_path / "MANO_RIGHT.pkl", override={"shapedirs": a})
    with pytest.raises(InputError) as err:
        load_mano_pkl(path)
    one_line_naming(err.value, path, "'shapedirs'", "itself")


# --------------------------------------------------------------------------------------------------------------------


def test_is_mano_pkl(tmp_path):
    assert is_mano_pkl(write_mano_pkl(tmp_path / "a.pkl"))
    assert is_mano_pkl(write_mano_pkl(tmp_path / "b.pkl", protocol=0, py2=False))
    save_npz(tube_hand(), tmp_path / "m.npz")
    assert not is_mano_pkl(tmp_path / "m.npz")
    (tmp_path / "t.txt").write_text("hello")
    assert not is_mano_pkl(tmp_path / "t.txt")
    assert not is_mano_pkl(tmp_path / "missing.pkl")
    assert not is_mano_pkl(tmp_path)


def test_struct_is_used_for_binstring_lengths():
    # Large byte strings are written with a 4-byte little-endian length, as Python 2 did.
    data = dumps_like_mano({"x": np.zeros(100)})
    assert pickle.BINSTRING + struct.pack("<i", 800) in data
