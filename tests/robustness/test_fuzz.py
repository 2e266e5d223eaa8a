"""Property-based fuzzing of every loader and file contract (hypothesis; CI draws a fixed example sequence, see
tests/conftest.py). Each loader, given a mutated or generated file, returns what it reads or raises one InputError:
no other exception, no crash, no file outside opened, nothing hanging on a FIFO.

    pickle      MANO pickles with bytes flipped, cut, or opcodes inserted            model.mano_pkl.load_mano_pkl
    npz         darthand models with a field re-shaped, re-typed or given odd values  model.npz_io.load_npz
    JSON        pose, lights, camera, jobs, catalogue and asset.json documents with a leaf replaced by any JSON
                value (NaN, Infinity, huge integers, deep nesting), or generated whole
    USD         a package with sublayers, references, payloads and texture paths of every kind (inside, missing,
                outside, absolute, a link leaving the package, a FIFO, a folder, an expression)
    glTF        a .gltf with buffer and image URIs of every kind and any leaf of its JSON replaced
"""

from __future__ import annotations

import importlib
import io
import json
import os
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from probe import Watch

from darthand.errors import InputError

FUZZ = settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))
SLOW_FUZZ = settings(max_examples=8, deadline=None, suppress_health_check=list(HealthCheck))
VALIDATOR_FUZZ = settings(SLOW_FUZZ, max_examples=4)    # each example starts the Khronos validator (node): ~4 s


# ------------------------------------------------------------------------------------------------ JSON values

def json_leaves():
    return (st.none() | st.booleans() | st.integers(-2 ** 70, 2 ** 70) | st.floats(allow_nan=True, allow_infinity=True)
            | st.text(max_size=8) | st.sampled_from([10 ** 400, -1e308, 5e-324, "../../etc/passwd", "/dev/zero"]))


def json_values(depth=4):
    return st.recursive(json_leaves(), lambda inner: st.lists(inner, max_size=4)
                        | st.dictionaries(st.text(max_size=6), inner, max_size=4), max_leaves=12)


def leaf_paths(doc, prefix=()):
    """Every path (tuple of keys/indices) to a leaf or container of a JSON document."""
    yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from leaf_paths(v, prefix + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from leaf_paths(v, prefix + (i,))


def replaced(doc, path, value):
    if not path:
        return value
    out = dict(doc) if isinstance(doc, dict) else list(doc)
    out[path[0]] = replaced(doc[path[0]], path[1:], value)
    return out


class Nested:
    """A JSON value wrapped in `depth` arrays (written as text: json.dumps itself recurses)."""

    def __init__(self, value, depth: int):
        self.value, self.depth = value, depth


def mutated(doc, data) -> object:
    """`doc` with one part replaced by any JSON value, or deeply nested, or generated whole."""
    kind = data.draw(st.sampled_from(["replace", "replace", "replace", "nest", "whole"]))
    if kind == "whole":
        return data.draw(json_values())
    paths = list(leaf_paths(doc))
    path = data.draw(st.sampled_from(paths))
    value = data.draw(json_values())
    if kind == "nest":
        value = Nested(value, data.draw(st.integers(60, 3000)))
    return replaced(doc, path, value)


def write_doc(path: Path, doc) -> Path:
    nested = []

    def default(x):
        if isinstance(x, Nested):
            nested.append(x)
            return "__NESTED__"
        raise TypeError(type(x))

    text = json.dumps(doc, allow_nan=True, default=default)
    for n in nested:
        text = text.replace('"__NESTED__"', "[" * n.depth + json.dumps(n.value, allow_nan=True) + "]" * n.depth, 1)
    path.write_text(text)
    return path


def loads_or_input_error(fn, *args):
    """fn(*args); an InputError is a handled outcome (returned as None)."""
    try:
        return fn(*args)
    except InputError as e:
        assert "\n" not in str(e) and str(e).strip(), repr(e)
        return None


# ------------------------------------------------------------------------------------------------ pickles

@pytest.fixture(scope="module")
def mano_bytes(tmp_path_factory) -> bytes:
    from mano_fixture import write_mano_pkl

    return write_mano_pkl(tmp_path_factory.mktemp("pkl") / "MANO_RIGHT.pkl").read_bytes()


OPCODES = [bytes([b]) for b in b"()0123456789.N]}tlsuabcdehijkqrFGILKMJRST\x80\x81\x82\x83\x84\x85\x86\x87\x88\x89"
                                b"\x8a\x8b\x8c\x8d\x8e\x8f\x90\x91\x92\x93\x94\x95"]


@FUZZ
@given(data=st.data())
def test_pickle_loader_never_fails_unhandled(mano_bytes, tmp_path_factory, data):
    from darthand.model.mano_pkl import load_mano_pkl

    raw = bytearray(mano_bytes)
    for _ in range(data.draw(st.integers(1, 6))):
        how = data.draw(st.sampled_from(["flip", "cut", "insert"]))
        at = data.draw(st.integers(0, max(len(raw) - 1, 0)))
        if how == "flip" and raw:
            raw[at] = data.draw(st.integers(0, 255))
        elif how == "cut":
            del raw[at:at + data.draw(st.integers(1, 4096))]
        else:
            raw[at:at] = b"".join(data.draw(st.lists(st.sampled_from(OPCODES), min_size=1, max_size=8)))
    path = tmp_path_factory.mktemp("p") / "MANO_RIGHT.pkl"
    path.write_bytes(bytes(raw))
    loads_or_input_error(load_mano_pkl, path)


@FUZZ
@given(depth=st.integers(101, 300_000), container=st.sampled_from(["tuple", "frozenset", "list", "dict"]))
def test_pickles_nested_too_deep_are_refused_before_unpickling(tmp_path_factory, depth, container):
    from darthand.model.mano_pkl import load_mano_pkl
    from darthand.safe_pickle import MAX_PICKLE_DEPTH

    body = {"tuple": b"K\x00" + b"\x85" * depth, "frozenset": b"(" * depth + b"\x91" * depth,
            "list": b"](" * depth + b"e" * depth, "dict": b"}K\x01" * depth + b"s" * depth}[container]
    path = tmp_path_factory.mktemp("p") / "m.pkl"
    path.write_bytes(b"\x80\x04}" + body + b"K\x01s.")         # as a dict key: hashing it recursed in C
    with pytest.raises(InputError, match=f"more than {MAX_PICKLE_DEPTH} levels"):
        load_mano_pkl(path)


# ------------------------------------------------------------------------------------------------ npz models

@pytest.fixture(scope="module")
def model_arrays(fx) -> dict:
    with np.load(fx / "model" / "right.npz") as z:
        return {k: z[k] for k in z.files}


def odd_array(data):
    kind = data.draw(st.sampled_from(["f8", "i8", "i1", "u4", "f4", "c16", "U5", "b1"]))
    shape = tuple(data.draw(st.lists(st.integers(0, 5), max_size=3)))
    values = data.draw(st.sampled_from([0, 1, -1, 2 ** 40, -(2 ** 62), 1e300, float("nan"), float("inf")]))
    with np.errstate(all="ignore"):
        try:
            return np.full(shape, values).astype(kind)
        except (ValueError, OverflowError):
            return np.zeros(shape, kind)


@FUZZ
@given(data=st.data())
def test_npz_loader_returns_a_sound_model_or_one_error(model_arrays, tmp_path_factory, data):
    from darthand.model.forward import forward
    from darthand.model.npz_io import load_npz

    arrays = dict(model_arrays)
    for _ in range(data.draw(st.integers(1, 3))):
        field = data.draw(st.sampled_from(sorted(arrays) + ["extra"]))
        how = data.draw(st.sampled_from(["replace", "poke", "drop"]))
        if how == "drop" and field in arrays:
            arrays.pop(field)
        elif how == "poke" and field in arrays and arrays[field].size and arrays[field].dtype.kind in "iuf":
            a = arrays[field].copy()
            flat = a.reshape(-1)
            value = data.draw(st.sampled_from([-1, 0, 10 ** 9, -(10 ** 9), 2 ** 31]) if a.dtype.kind in "iu" else
                              st.sampled_from([np.nan, np.inf, -1e300, 1e7]))
            with np.errstate(all="ignore"):
                flat[data.draw(st.integers(0, flat.size - 1))] = np.array(value).astype(a.dtype)
            arrays[field] = a
        else:
            arrays[field] = odd_array(data)
    path = tmp_path_factory.mktemp("n") / "m.npz"
    np.savez(path, **arrays)
    model = loads_or_input_error(load_npz, path)
    if model is not None:          # what loads must pose without reading outside its arrays, and stay finite
        posed = forward(model, np.zeros((1, 48)))
        assert np.isfinite(posed.vertices).all() and np.isfinite(posed.joints).all()


@FUZZ
@given(data=st.data())
def test_npz_member_headers_are_checked_before_anything_is_read(model_arrays, tmp_path_factory, data):
    from darthand.model.npz_io import load_npz

    member = data.draw(st.sampled_from(sorted(model_arrays)))
    shape = tuple(data.draw(st.lists(st.integers(0, 10 ** 30), max_size=4)))
    descr = data.draw(st.sampled_from(["<f8", "<i8", "|O", "<U3", "|b1", "[('a', '<f8')]", "garbage"]))
    header = f"{{'descr': {descr!r}, 'fortran_order': False, 'shape': {shape!r}, }}".encode()
    header += b" " * (63 - (len(header) + 10) % 64) + b"\n"
    raw = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + b"\0" * data.draw(st.integers(0, 64))
    path = tmp_path_factory.mktemp("n") / "m.npz"
    with zipfile.ZipFile(path, "w") as z:
        for k, v in model_arrays.items():
            buf = io.BytesIO()
            np.save(buf, v)
            z.writestr(f"{k}.npy", raw if k == member else buf.getvalue())
    loads_or_input_error(load_npz, path)


# ------------------------------------------------------------------------------------------------ JSON contracts

POSE_DOC = {"pose": [[0.1] * 48, [0.0] * 48], "betas": [0.5, -0.5], "flat_hand_mean": False}
LIGHTS_DOC = {"ambient": {"color": [1, 1, 1], "intensity": 0.2},
              "lights": [{"type": "directional", "direction": [0, 0, 1], "intensity": 1.0, "frame": "camera"},
                         {"type": "point", "position": [0.1, 0.2, 0.3], "color": [1, 0.5, 0.5], "shadows": False}]}
CAMERA_DOCS = [{"width": 64, "height": 48, "fov_deg": 40, "view": "dorsal", "distance": 0.5, "roll_deg": 10},
               {"K": [[50, 0, 32], [0, 50, 32], [0, 0, 1]], "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                "t": [0, 0, 1], "width": 64, "height": 64},
               {"look_at": {"eye": [0, 0, 1], "target": [0, 0, 0], "up": [0, 1, 0]}, "focal_px": 80}]
JOBS_DOC = {"frames": [{"index": 0, "pose": "fist", "texture": "plain", "camera": {"view": "dorsal"},
                        "skin_tone_offset": 0.05, "lights": LIGHTS_DOC}]}


def test_a_pose_file_of_a_line_break_is_refused_in_one_line(tmp_path):
    """What hypothesis found: a document that is the string "\\n" is named in the message without breaking it."""
    from darthand.model.poses import load_pose_file

    assert loads_or_input_error(load_pose_file, write_doc(tmp_path / "pose.json", "\n")) is None


@FUZZ
@given(data=st.data())
def test_pose_files(tmp_path_factory, data):
    from darthand.model.forward import forward
    from darthand.model.load import open_hand
    from darthand.model.poses import load_pose_file

    path = write_doc(tmp_path_factory.mktemp("j") / "pose.json", mutated(POSE_DOC, data))
    result = loads_or_input_error(load_pose_file, path)
    if result is not None:         # what loads poses the hand (or is refused there, by name) and stays finite
        pose, betas, flat = result
        posed = loads_or_input_error(lambda: forward(open_hand(), pose, None if betas is None else betas[..., :0],
                                                     flat_hand_mean=flat))
        assert posed is None or np.isfinite(posed.vertices).all()


@FUZZ
@given(data=st.data())
def test_lights_files(tmp_path_factory, data):
    from darthand.render.lights import load_lighting, world_lights

    path = write_doc(tmp_path_factory.mktemp("j") / "lights.json", mutated(LIGHTS_DOC, data))
    lighting = loads_or_input_error(load_lighting, path)
    if lighting is not None:
        for light in world_lights(lighting, np.eye(3), np.zeros(3)):
            assert np.isfinite(light["radiance"]).all()
        assert np.isfinite(lighting.ambient).all()


@FUZZ
@given(data=st.data(), which=st.sampled_from(range(len(CAMERA_DOCS))))
def test_camera_files(tmp_path_factory, data, which):
    from darthand.render.camera import load_camera

    points = np.random.default_rng(0).normal(scale=0.05, size=(50, 3))
    path = write_doc(tmp_path_factory.mktemp("j") / "camera.json", mutated(CAMERA_DOCS[which], data))
    cam = loads_or_input_error(load_camera, path, points)
    if cam is not None:
        uv, z = cam.project(points)
        assert np.isfinite(cam.K).all() and np.isfinite(cam.t).all() and cam.width * cam.height <= 16384 ** 2


def _load_jobs():
    for module in ("darthand.dataset.jobs", "darthand.dataset", "darthand.render.dataset"):
        try:
            return importlib.import_module(module).load_jobs
        except (ImportError, AttributeError):
            continue
    raise AssertionError("no load_jobs: the dataset stage's jobs loader moved; point this test at it")


@FUZZ
@given(data=st.data())
def test_jobs_files(tmp_path_factory, data):
    path = write_doc(tmp_path_factory.mktemp("j") / "jobs.json", mutated(JOBS_DOC, data))
    loads_or_input_error(_load_jobs(), path)


@FUZZ
@given(data=st.data(), kind=st.sampled_from(["tex", "acc"]))
def test_catalogues(fx, tmp_path_factory, data, kind):
    from darthand.accessories.loader import load_accessory_catalog
    from darthand.textures.loader import load_texture_catalog

    folder = tmp_path_factory.mktemp("c") / kind
    shutil.copytree(fx / kind, folder)
    doc = json.loads((folder / "catalog.json").read_text())
    write_doc(folder / "catalog.json", mutated(doc, data))
    watch = Watch([fx / kind / "catalog.json"])
    loads_or_input_error(load_texture_catalog if kind == "tex" else load_accessory_catalog, folder)
    assert watch.opened() == []          # the catalogue's files are only read from its own folder


@FUZZ
@given(data=st.data())
def test_asset_json(fx, tmp_path_factory, data):
    from darthand.export.package_files import read_asset_info
    from darthand.export.usdz import interface_layer

    folder = tmp_path_factory.mktemp("a") / "right"
    folder.mkdir()
    doc = json.loads((fx / "usd" / "right" / "asset.json").read_text())
    write_doc(folder / "asset.json", mutated(doc, data))
    info = loads_or_input_error(read_asset_info, folder)
    if info is not None:
        layer = loads_or_input_error(interface_layer, folder)
        assert layer is None or layer.parent == folder


# ------------------------------------------------------------------------------------------------ packages

PATH_KINDS = ["inside", "missing", "outside-relative", "outside-absolute", "link-outside", "fifo", "folder",
              "expression", "uri"]
UNSAFE = {"outside-relative", "outside-absolute", "link-outside", "fifo", "folder"}


def authored(kind: str, pkg: Path, outside: Path, name: str, ext: str) -> str:
    """An asset path of `kind` as a layer inside `pkg` would author it (creating what it points to)."""
    if kind == "inside":
        shutil.copy(outside / f"secret{ext}", pkg / f"{name}{ext}")
        return f"./{name}{ext}"
    if kind == "missing":
        return f"./nothing_{name}{ext}"
    if kind == "outside-relative":
        return f"../outside/secret{ext}"
    if kind == "outside-absolute":
        return str(outside / f"secret{ext}")
    if kind == "link-outside":
        os.symlink(outside / f"secret{ext}", pkg / f"{name}{ext}")
        return f"./{name}{ext}"
    if kind == "fifo":
        os.mkfifo(pkg / f"{name}{ext}")
        return f"./{name}{ext}"
    if kind == "folder":
        (pkg / f"{name}{ext}").mkdir()
        return f"./{name}{ext}"
    if kind == "expression":
        return "`\"./${NAME}" + ext + "\"`"
    return f"https://example.invalid/{name}{ext}"


def usd_package(fx: Path, root: Path) -> tuple[Path, Path]:
    pkg = root / "pkg"
    shutil.copytree(fx / "usd" / "right", pkg)
    outside = root / "outside"
    outside.mkdir()
    (outside / "secret.usda").write_text('#usda 1.0\n\ndef Xform "Secret"\n{\n}\n')
    shutil.copy(pkg / "texture" / "brown_moles_00" / "brown_moles_00.png", outside / "secret.png")
    return pkg, outside


def add_arcs(pkg: Path, outside: Path, kinds: list[tuple[str, str]]) -> None:
    """Author, on the interface layer, one arc (sublayer, reference, payload or texture path) per (arc, kind)."""
    text = (pkg / "right.usda").read_text()
    sublayers, prims = [], []
    for i, (arc, kind) in enumerate(kinds):
        ext = ".png" if arc == "texture" else ".usda"
        path = authored(kind, pkg, outside, f"a{i}", ext)
        if arc == "sublayer":
            sublayers.append(f"@{path}@")
        elif arc == "texture":
            prims.append(f'def Shader "T{i}"\n{{\n    uniform token info:id = "UsdUVTexture"\n'
                         f'    asset inputs:file = @{path}@\n}}\n')
        else:
            prims.append(f'def Xform "X{i}" (\n    prepend {"references" if arc == "reference" else "payload"} = '
                         f'@{path}@\n)\n{{\n}}\n')
    if sublayers:
        text = text.replace("    defaultPrim", f"    subLayers = [{', '.join(sublayers)}]\n    defaultPrim", 1)
    (pkg / "right.usda").write_text(text + "\n" + "\n".join(prims))


ARCS = st.lists(st.tuples(st.sampled_from(["sublayer", "reference", "payload", "texture"]),
                          st.sampled_from(PATH_KINDS)), min_size=1, max_size=5)


def package_with(fx: Path, root: Path, arcs) -> tuple[Path, Watch]:
    """A copy of the fixture package with `arcs` authored, and a watch on the files outside it."""
    pkg, outside = usd_package(fx, root)
    add_arcs(pkg, outside, arcs)
    return pkg, Watch([outside / "secret.usda", outside / "secret.png"])


@FUZZ
@given(arcs=ARCS)
def test_usd_pre_check_flags_exactly_what_must_not_be_opened(fx, tmp_path_factory, arcs):
    from darthand.export.package_files import usd_problems

    pkg, watch = package_with(fx, tmp_path_factory.mktemp("u"), arcs)
    problems = usd_problems(pkg / "right.usda")
    assert watch.opened() == []
    flagged = {p.asset for p in problems}
    for i, (arc, kind) in enumerate(arcs):
        if kind in UNSAFE:
            assert any(f"a{i}" in a or "outside" in a for a in flagged), (arc, kind, problems)
    assert all(p.reason for p in problems)
    assert not [p for p in problems if p.role == "layer" and not any(k in UNSAFE | {"expression", "uri"}
                                                                     for _, k in arcs)]


@SLOW_FUZZ
@given(arcs=ARCS)
def test_validate_and_render_never_open_what_leaves_a_usd_package(fx, tmp_path_factory, arcs):
    from darthand.render.api import open_source
    from darthand.validate.run import validate_paths

    pkg, watch = package_with(fx, tmp_path_factory.mktemp("u"), arcs)
    report = validate_paths([pkg])
    assert report.exit_code in (0, 1, 2)
    if any(kind in UNSAFE for _, kind in arcs):
        assert report.exit_code != 0
        loads_or_input_error(lambda: open_source(pkg, model=fx / "model" / "right.npz"))
    assert watch.opened() == []


def gltf_copy(fx: Path, root: Path) -> tuple[Path, Path]:
    pkg = root / "pkg"
    shutil.copytree(fx / "gltf", pkg)
    outside = root / "outside"
    outside.mkdir()
    shutil.copy(pkg / "right.bin", outside / "secret.bin")
    shutil.copy(pkg / "textures" / "brown_moles_00_albedo.png", outside / "secret.png")
    return pkg / "right.gltf", outside


@FUZZ
@given(data=st.data())
def test_gltf_reader(fx, tmp_path_factory, data):
    from darthand.validate.gltf_reader import Unreadable, read_gltf

    path, outside = gltf_copy(fx, tmp_path_factory.mktemp("g"))
    doc = json.loads(path.read_text())
    for key, ext in (("buffers", ".bin"), ("images", ".png")):
        kind = data.draw(st.sampled_from(PATH_KINDS))
        doc[key][0]["uri"] = authored(kind, path.parent, outside, f"u{key}", ext).replace(".usda", ext)
    if data.draw(st.booleans()):
        doc = mutated(doc, data)
    write_doc(path, doc)
    watch = Watch([outside / "secret.bin", outside / "secret.png"])
    try:
        read_gltf(path)
    except Unreadable as e:
        assert "\n" not in str(e)
    assert watch.opened() == []


@VALIDATOR_FUZZ
@given(data=st.data())
def test_validate_with_the_khronos_validator_never_opens_outside_files(fx, tmp_path_factory, data):
    from darthand.validate.run import validate_paths

    path, outside = gltf_copy(fx, tmp_path_factory.mktemp("g"))
    doc = json.loads(path.read_text())
    kinds = {key: data.draw(st.sampled_from(PATH_KINDS)) for key in ("buffers", "images")}
    for key, ext in (("buffers", ".bin"), ("images", ".png")):
        doc[key][0]["uri"] = authored(kinds[key], path.parent, outside, f"u{key}", ext)
    write_doc(path, doc)
    watch = Watch([outside / "secret.bin", outside / "secret.png"])
    report = validate_paths([path])
    assert watch.opened() == []
    if set(kinds.values()) & UNSAFE:
        assert report.exit_code != 0
