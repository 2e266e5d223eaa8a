"""The hostile-input corpus: bad inputs for every command, by input class, each with what handling it means.

A `Case` is a darthand command line (placeholders `{t}`: the case's own folder, `{fx}`: the fixture folder of
probe_fixtures.py), an optional `setup(t, fx)` that writes its bad input, the exit codes that count as handled (2, a
one-line error, by default), files that must never be opened (`watch`: files outside a package), and an optional `check`
of what the command left behind. The probe (probe.py) runs every case through the real CLI in a subprocess and judges
it: hang, crash (signal), outside file opened, payload executed, traceback, wrong exit code, orphan processes, noise on
stderr, or the case's own check failing -- else handled.

Cases that need more than one command (interrupting a run, a SIGKILL and a re-run, damaging a build) have a `run`
function instead; the probe gives it the same judging helpers.
"""

from __future__ import annotations

import io
import json
import os
import pickle
import shutil
import struct
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

ZEROS48 = [0.0] * 48


@dataclass
class Case:
    klass: str
    name: str
    argv: list[str] | None = None
    setup: Callable[[Path, Path], None] | None = None
    expect: tuple[int, ...] = (2,)
    watch: tuple[str, ...] = ()
    canary: str | None = None             # a file a malicious payload would create
    check: Callable[[Path, Path], str | None] | None = None   # (t, fx) -> problem or None, after the run
    timeout: float = 60.0
    run: Callable | None = None           # custom runner: run(case, t, fx, tools) -> Result

    @property
    def id(self) -> str:
        return f"{self.klass} / {self.name}"


CASES: list[Case] = []


def case(klass: str, name: str, argv=None, **kw) -> Case:
    c = Case(klass, name, argv, **kw)
    CASES.append(c)
    return c


# ------------------------------------------------------------------------------------------------ writers


def fifo(path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    os.mkfifo(path)


def text(path: Path, content: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(content)


def data(path: Path, content: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(content)


def deep(n: int, inner: str = "0", kind: str = "list") -> str:
    if kind == "list":
        return "[" * n + inner + "]" * n
    return '{"a":' * n + inner + "}" * n


def symlink(path: Path, target) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    os.symlink(target, path)


def writer(path: str, content) -> Callable[[Path, Path], None]:
    """setup writing `content` (str, bytes, or a JSON-able object) to `{t}/path`."""
    def setup(t: Path, fx: Path) -> None:
        p = t / path
        if isinstance(content, bytes):
            data(p, content)
        elif isinstance(content, str):
            text(p, content)
        else:
            text(p, json.dumps(content))
    return setup


def fifo_at(path: str) -> Callable[[Path, Path], None]:
    return lambda t, fx: fifo(t / path)


def chain(*setups) -> Callable[[Path, Path], None]:
    def setup(t: Path, fx: Path) -> None:
        for s in setups:
            s(t, fx)
    return setup


# ------------------------------------------------------------------------------------------------ npz models


def model_arrays(fx: Path) -> dict:
    with np.load(fx / "model" / "right.npz", allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def npz_edit(name: str, edit: Callable[[dict], None], compressed: bool = False):
    """setup: the fixture model with `edit(arrays)` applied, saved as {t}/name."""
    def setup(t: Path, fx: Path) -> None:
        arrays = model_arrays(fx)
        edit(arrays)
        t.mkdir(parents=True, exist_ok=True)
        (np.savez_compressed if compressed else np.savez)(t / name, **arrays)
    return setup


def npy_bytes(shape, descr: str = "<f8", payload: bytes = b"\0" * 64) -> bytes:
    """A .npy member whose header declares `shape` (possibly a lie) followed by `payload`."""
    header = repr({"descr": descr, "fortran_order": False, "shape": tuple(shape)}).encode()
    header += b" " * (63 - (len(header) + 10) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header + payload


def npz_member(name: str, member: str, raw: bytes):
    """setup: the fixture model with member `member`.npy replaced by raw bytes."""
    def setup(t: Path, fx: Path) -> None:
        arrays = model_arrays(fx)
        t.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(t / name, "w") as z:
            for k, v in arrays.items():
                if k != member:
                    buf = io.BytesIO()
                    np.save(buf, v, allow_pickle=False)
                    z.writestr(f"{k}.npy", buf.getvalue())
            z.writestr(f"{member}.npy", raw)
    return setup


def set_(key, value):
    def edit(a: dict) -> None:
        a[key] = value
    return edit


def regressor_edit(fn):
    def edit(a: dict) -> None:
        fn(a)
    return edit


# ------------------------------------------------------------------------------------------------ pickles


def pkl_override(name: str, **override):
    def setup(t: Path, fx: Path) -> None:
        from mano_fixture import write_mano_pkl
        t.mkdir(parents=True, exist_ok=True)
        write_mano_pkl(t / name, override=override)
    return setup


def pkl_bytes(name: str, fn: Callable[[Path, bytes], bytes]):
    """setup: fn(t, bytes of the fixture pickle) written as {t}/name."""
    def setup(t: Path, fx: Path) -> None:
        data(t / name, fn(t, (fx / "MANO_RIGHT.pkl").read_bytes()))
    return setup


def with_item(key: str, payload: bytes) -> Callable[[Path, bytes], bytes]:
    """The pickle's top-level dict gets key -> the object `payload` builds (SETITEM appended before STOP)."""
    def fn(t: Path, base: bytes) -> bytes:
        assert base.endswith(pickle.STOP)
        k = key.encode()
        return base[:-1] + pickle.SHORT_BINSTRING + bytes([len(k)]) + k + payload + pickle.SETITEM + pickle.STOP
    return fn


def _pickle_ops():
    """mano_fixture's opcode writers: GLOBAL, BINUNICODE, a call (MARK args TUPLE REDUCE)."""
    from mano_fixture import _call, _global, _text

    return _global, _text, _call


g, utext, call = _pickle_ops()


def touch_cmd(t: Path) -> str:
    return f"touch {t}/PWNED"


def malicious(kind: str) -> Callable[[Path, bytes], bytes]:
    """A payload that, if run, creates {t}/PWNED."""
    def fn(t: Path, base: bytes) -> bytes:
        cmd = touch_cmd(t)
        py = f"open('{t}/PWNED','w').close()"
        body = {
            "os.system": call(g("os", "system"), utext(cmd)),
            "posix.system": call(g("posix", "system"), utext(cmd)),
            "builtins.eval": call(g("builtins", "eval"), utext(py)),
            "builtins.exec": call(g("builtins", "exec"), utext(py)),
            "__builtin__.eval": call(g("__builtin__", "eval"), utext(py)),
            "subprocess.Popen": call(g("subprocess", "Popen"), pickle.MARK + utext("touch") + utext(f"{t}/PWNED")
                                     + pickle.LIST),
            "subprocess.run": call(g("subprocess", "run"), utext(cmd)),
            "importlib": call(call(g("importlib", "import_module"), utext("os")), utext(cmd)),
            "getattr chain": call(call(g("builtins", "getattr"), g("os", "system"), utext("__call__")), utext(cmd)),
            "protocol 4 STACK_GLOBAL": (utext("os") + utext("system") + pickle.STACK_GLOBAL + pickle.MARK
                                        + utext(cmd) + pickle.TUPLE + pickle.REDUCE),
            "INST opcode": pickle.MARK + pickle.INST + b"os\nsystem\n" + utext(cmd)[0:0]
            + b"",   # filled below (INST takes its args from the mark)
            "OBJ opcode": pickle.MARK + g("os", "system") + utext(cmd) + pickle.OBJ,
            "NEWOBJ of os.system": g("os", "system") + pickle.MARK + utext(cmd) + pickle.TUPLE + pickle.NEWOBJ,
            "EXT1 registry": pickle.EXT1 + b"\x01",
            "nested in Ch state": (g("chumpy.ch", "Ch") + pickle.EMPTY_TUPLE + pickle.NEWOBJ + pickle.EMPTY_DICT
                                   + pickle.SHORT_BINSTRING + b"\x01x" + call(g("os", "system"), utext(cmd))
                                   + pickle.SETITEM + pickle.BUILD),
            "reduce inside ndarray state": call(g("numpy.core.multiarray", "_reconstruct"), g("numpy", "ndarray"),
                                                pickle.MARK + pickle.BININT1 + b"\x00" + pickle.TUPLE,
                                                pickle.SHORT_BINSTRING + b"\x01b")
            + pickle.MARK + pickle.BININT1 + b"\x01" + call(g("os", "system"), utext(cmd)) + pickle.TUPLE
            + pickle.BUILD,
            "persistent id": utext("x") + pickle.BINPERSID,
            "BUILD sets __dict__ of a guard": g("numpy", "dtype") + pickle.EMPTY_DICT + pickle.BUILD,
            "copyreg._reconstructor of os": call(g("copy_reg", "_reconstructor"), g("os", "system"),
                                                 g("__builtin__", "object"), pickle.NONE),
            "builtins.__import__": call(g("builtins", "__import__"), utext("os")),
            "numpy.load": call(g("numpy", "load"), utext(f"{t}/x.npy")),
            "numpy.testing runner": call(g("numpy.testing._private.utils", "runstring"), utext(py),
                                         pickle.EMPTY_DICT),
            "pickle.loads inner": call(g("pickle", "loads"), pickle.SHORT_BINBYTES + b"\x01."),
            "scipy sparse called": call(g("scipy.sparse._csc", "csc_matrix"), utext(cmd)),
        }[kind]
        if kind == "INST opcode":
            body = pickle.MARK + utext(cmd) + pickle.INST + b"os\nsystem\n"
        return with_item("bs_style", body)(t, base)
    return fn


MALICIOUS = ("os.system", "posix.system", "builtins.eval", "builtins.exec", "__builtin__.eval", "subprocess.Popen",
             "subprocess.run", "importlib", "getattr chain", "protocol 4 STACK_GLOBAL", "INST opcode", "OBJ opcode",
             "NEWOBJ of os.system", "EXT1 registry", "nested in Ch state", "reduce inside ndarray state",
             "persistent id", "BUILD sets __dict__ of a guard", "copyreg._reconstructor of os",
             "builtins.__import__", "numpy.load", "numpy.testing runner", "pickle.loads inner",
             "scipy sparse called")


def deep_tuple(n: int) -> bytes:
    return pickle.BININT1 + b"\x00" + pickle.TUPLE1 * n


def deep_frozenset(n: int) -> bytes:
    return pickle.MARK * n + pickle.FROZENSET * n


def deep_list(n: int) -> bytes:
    return (pickle.EMPTY_LIST + pickle.MARK) * n + (pickle.APPENDS) * n


# ------------------------------------------------------------------------------------------------ packages


def usd_pkg(t: Path, fx: Path) -> Path:
    """A copy of the fixture USD package at {t}/pkg/right; an outside folder {t}/outside with a secret layer,
    payload, image and binary."""
    pkg = t / "pkg" / "right"
    shutil.copytree(fx / "usd" / "right", pkg)
    outside = t / "outside"
    outside.mkdir(parents=True, exist_ok=True)
    text(outside / "secret.usda", '#usda 1.0\n\ndef Xform "Secret"\n{\n}\n')
    shutil.copy(pkg / "payload.usdc", outside / "payload.usdc")
    shutil.copy(pkg / "texture" / "brown_moles_00" / "brown_moles_00.png", outside / "secret.png")
    return pkg


def edit_text(path: Path, old: str, new: str) -> None:
    s = path.read_text()
    assert old in s, (path, old)
    path.write_text(s.replace(old, new, 1))


def usd_edit(fn):
    def setup(t: Path, fx: Path) -> None:
        fn(t, usd_pkg(t, fx))
    return setup


def add_sublayer(target: str):
    def fn(t: Path, pkg: Path) -> None:
        target_ = target.replace("{t}", str(t))
        edit_text(pkg / "right.usda", "    defaultPrim", f"    subLayers = [@{target_}@]\n    defaultPrim")
    return fn


def gltf_pkg(t: Path, fx: Path) -> Path:
    pkg = t / "pkg"
    shutil.copytree(fx / "gltf", pkg)
    outside = t / "outside"
    outside.mkdir(parents=True, exist_ok=True)
    shutil.copy(pkg / "right.bin", outside / "secret.bin")
    shutil.copy(pkg / "textures" / "brown_moles_00_albedo.png", outside / "secret.png")
    return pkg / "right.gltf"


def gltf_edit(fn):
    def setup(t: Path, fx: Path) -> None:
        path = gltf_pkg(t, fx)
        doc = json.loads(path.read_text())
        fn(t, path.parent, doc)
        path.write_text(json.dumps(doc))
    return setup


def buffer_uri(uri: str):
    def fn(t, pkg, doc):
        doc["buffers"][0]["uri"] = uri.replace("{t}", str(t))
    return fn


def image_uri(uri: str):
    def fn(t, pkg, doc):
        doc["images"][0]["uri"] = uri.replace("{t}", str(t))
    return fn


# ================================================================================================ the cases

INFO = ["model", "info"]
POSE = ["model", "pose", "open", "--out", "{t}/posed.npz", "--pose"]
RENDER = ["render", "{fx}/model/right.npz", "--textures", "{fx}/tex", "--accessories", "{fx}/acc", "--out",
          "{t}/out", "--size", "48"]
RENDER_USD = ["render", "{t}/pkg/right", "--out", "{t}/out", "--size", "48", "--model", "{fx}/model/right.npz"]
VALIDATE = ["validate"]

# ---------------------------------------------------------------- pickles: payloads
for kind in MALICIOUS:
    case("pickle: code-running payloads", kind, INFO + ["{t}/MANO_RIGHT.pkl"],
         setup=pkl_bytes("MANO_RIGHT.pkl", malicious(kind)), canary="{t}/PWNED")

# ---------------------------------------------------------------- pickles: malformed, deep, huge
for key in ("v_template", "hands_mean", "shapedirs"):
    case("pickle: malformed, deep, huge", f"deep tuple in {key}", INFO + ["{t}/m.pkl"],
         setup=pkl_bytes("m.pkl", with_item(key, deep_tuple(200_000))))
case("pickle: malformed, deep, huge", "deep tuple as a dict key", INFO + ["{t}/m.pkl"],
     setup=writer("m.pkl", b"\x80\x04}" + deep_tuple(1_000_000) + b"K\x01s."))
case("pickle: malformed, deep, huge", "deep tuple in a frozenset", INFO + ["{t}/m.pkl"],
     setup=writer("m.pkl", b"\x80\x04(" + deep_tuple(1_000_000) + b"\x91."))
case("pickle: malformed, deep, huge", "deep frozenset in a field", INFO + ["{t}/m.pkl"],
     setup=pkl_bytes("m.pkl", with_item("v_template", deep_frozenset(200_000))))
case("pickle: malformed, deep, huge", "deep frozenset key", INFO + ["{t}/m.pkl"],
     setup=writer("m.pkl", b"\x80\x04}" + deep_frozenset(300_000) + b"K\x01s."))
case("pickle: malformed, deep, huge", "deep list", INFO + ["{t}/m.pkl"],
     setup=pkl_bytes("m.pkl", with_item("v_template", deep_list(200_000))))
case("pickle: malformed, deep, huge", "deep dict", INFO + ["{t}/m.pkl"],
     setup=pkl_bytes("m.pkl", with_item("weights", (pickle.EMPTY_DICT + pickle.BININT1 + b"\x01") * 200_000
                                        + pickle.SETITEM * 200_000)))
case("pickle: malformed, deep, huge", "int with 5000 digits as a shape", INFO + ["{t}/m.pkl"],
     setup=pkl_bytes("m.pkl", with_item("v_template", call(
         g("numpy.core.multiarray", "_reconstruct"), g("numpy", "ndarray"),
         pickle.MARK + pickle.LONG + b"9" * 5000 + b"L\n" + pickle.TUPLE, pickle.SHORT_BINSTRING + b"\x01b"))))
case("pickle: malformed, deep, huge", "LONG4 of 10 MB", INFO + ["{t}/m.pkl"],
     setup=pkl_bytes("m.pkl", with_item("hands_mean", pickle.LONG4 + struct.pack("<i", 10_000_000)
                                        + b"\x7f" * 10_000_000)))
case("pickle: malformed, deep, huge", "ndarray state declaring 10^12 elements", INFO + ["{t}/m.pkl"],
     setup=pkl_bytes("m.pkl", with_item("v_template", call(
         g("numpy.core.multiarray", "_reconstruct"), g("numpy", "ndarray"),
         pickle.MARK + pickle.BININT1 + b"\x00" + pickle.TUPLE, pickle.SHORT_BINSTRING + b"\x01b")
         + pickle.MARK + pickle.BININT1 + b"\x01" + pickle.MARK + pickle.BININT + struct.pack("<i", 1_000_000)
         + pickle.BININT + struct.pack("<i", 1_000_000) + pickle.TUPLE + call(g("numpy", "dtype"),
                                                                               utext("f8"), pickle.NEWFALSE,
                                                                               pickle.NEWTRUE)
         + pickle.NEWFALSE + pickle.SHORT_BINBYTES + b"\x08" + b"\0" * 8 + pickle.TUPLE + pickle.BUILD)))
case("pickle: malformed, deep, huge", "Select with 10^30 preferred shape", INFO + ["{t}/m.pkl"],
     setup=pkl_bytes("m.pkl", with_item("shapedirs", g("chumpy.reordering", "Select") + pickle.EMPTY_TUPLE
                                        + pickle.NEWOBJ + pickle.MARK + utext("a") + pickle.EMPTY_LIST
                                        + utext("idxs") + pickle.EMPTY_LIST + utext("preferred_shape")
                                        + pickle.MARK + pickle.LONG + b"1" + b"0" * 30 + b"L\n" + pickle.TUPLE
                                        + pickle.DICT + pickle.BUILD)))
case("pickle: malformed, deep, huge", "regressor indices out of range", INFO + ["{t}/m.pkl"],
     setup=lambda t, fx: _pkl_regressor(t, "oob"))
case("pickle: malformed, deep, huge", "regressor indptr decreasing", INFO + ["{t}/m.pkl"],
     setup=lambda t, fx: _pkl_regressor(t, "indptr"))
case("pickle: malformed, deep, huge", "NaN in posedirs", INFO + ["{t}/m.pkl"],
     setup=lambda t, fx: _pkl_nan(t))
case("pickle: malformed, deep, huge", "truncated", INFO + ["{t}/m.pkl"],
     setup=pkl_bytes("m.pkl", lambda t, b: b[: len(b) // 2]))
case("pickle: malformed, deep, huge", "empty file", INFO + ["{t}/m.pkl"], setup=writer("m.pkl", b""))
case("pickle: malformed, deep, huge", "random bytes", INFO + ["{t}/m.pkl"],
     setup=writer("m.pkl", bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8))))
case("pickle: malformed, deep, huge", "memo GET of a missing entry", INFO + ["{t}/m.pkl"],
     setup=writer("m.pkl", b"\x80\x02h\x07."))
case("pickle: malformed, deep, huge", "a list, not a dict", INFO + ["{t}/m.pkl"], setup=writer("m.pkl", b"\x80\x02]."))


def _pkl_regressor(t: Path, how: str) -> None:
    import scipy.sparse as sp
    from mano_fixture import write_mano_pkl
    from synthetic import tube_hand

    m = tube_hand()
    r = sp.csc_matrix(m.J_regressor)
    if how == "oob":
        r.indices[:] = 10 ** 6
    else:
        r.indptr[3] = r.indptr[-1] + 5
    t.mkdir(parents=True, exist_ok=True)
    write_mano_pkl(t / "m.pkl", override={"J_regressor": r})


def _pkl_nan(t: Path) -> None:
    from mano_fixture import write_mano_pkl
    from synthetic import tube_hand

    m = tube_hand()
    p = m.posedirs.copy()
    p[5, 1, 7] = np.nan
    t.mkdir(parents=True, exist_ok=True)
    write_mano_pkl(t / "m.pkl", override={"posedirs": p})


# ---------------------------------------------------------------- npz: indices and shapes
def _oob_indices(a):
    a["J_regressor_indices"] = a["J_regressor_indices"].copy()
    a["J_regressor_indices"][3] = 10 ** 9


def _neg_indices(a):
    a["J_regressor_indices"] = a["J_regressor_indices"].copy()
    a["J_regressor_indices"][0] = -5


def _indptr_past(a):
    a["J_regressor_indptr"] = a["J_regressor_indptr"].copy()
    a["J_regressor_indptr"][-1] += 100


def _indptr_decreasing(a):
    p = a["J_regressor_indptr"].copy()
    p[4] = p[8] + 3
    a["J_regressor_indptr"] = p


NPZ_INDEX = {
    "regressor index past the vertices": _oob_indices,
    "regressor index 10^9 (pose)": _oob_indices,
    "regressor negative index": _neg_indices,
    "regressor indptr past the data": _indptr_past,
    "regressor indptr decreasing": _indptr_decreasing,
    "regressor indptr short": lambda a: a.__setitem__("J_regressor_indptr", a["J_regressor_indptr"][:5]),
    "regressor shape 3 numbers": set_("J_regressor_shape", np.array([16, 1769, 3])),
    "regressor shape 10^12 columns": set_("J_regressor_shape", np.array([16, 10 ** 12])),
    "regressor shape negative": set_("J_regressor_shape", np.array([-16, 1769])),
    "regressor indices as floats": lambda a: a.__setitem__("J_regressor_indices",
                                                           a["J_regressor_indices"].astype(np.float64) + 0.5),
    "regressor data shorter than indices": lambda a: a.__setitem__("J_regressor_data", a["J_regressor_data"][:3]),
    "faces index past the vertices": lambda a: a.__setitem__("faces", np.where(np.arange(a["faces"].size).reshape(
        a["faces"].shape) == 7, 10 ** 7, a["faces"])),
    "faces negative": lambda a: a.__setitem__("faces", -a["faces"]),
    "faces_uv past the UVs": lambda a: a.__setitem__("faces_uv", a["faces_uv"] + 10 ** 6),
    "face_labels past the label list": lambda a: a.__setitem__("face_labels", np.full_like(a["face_labels"], 100)),
    "tip_ids past the vertices": set_("tip_ids", np.array([0, 1, 2, 3, 10 ** 8])),
    "parents cycle": set_("parents", np.r_[-1, np.arange(15)[::-1]]),
    "parents huge": set_("parents", np.full(16, 2 ** 62)),
    "v_template NaN": lambda a: a.__setitem__("v_template", np.where(np.arange(a["v_template"].size).reshape(
        a["v_template"].shape) == 5, np.nan, a["v_template"])),
    "v_template 1e300": lambda a: a.__setitem__("v_template", a["v_template"] * 1e300),
    "posedirs 1e308": lambda a: a.__setitem__("posedirs", a["posedirs"] * 0 + 1e308),
    "weights as strings": lambda a: a.__setitem__("weights", a["weights"].astype(str)),
    "v_template complex": lambda a: a.__setitem__("v_template", a["v_template"].astype(np.complex128)),
    "v_template as a 0-d array": set_("v_template", np.array(1.0)),
    "faces structured dtype": lambda a: a.__setitem__("faces", np.zeros(3, dtype=[("a", "<i8"), ("b", "<f8")])),
    "uvs 2 columns short": lambda a: a.__setitem__("uvs", a["uvs"][:10]),
    "shapedirs 4-d": set_("shapedirs", np.zeros((1769, 3, 2, 2))),
    "hands_components wrong shape": set_("hands_components", np.zeros((3, 7))),
}
for name, edit in NPZ_INDEX.items():
    argv = (["model", "pose", "{t}/m.npz", "--out", "{t}/p.npz", "--pose", "{t}/pose.json"] if "(pose)" in name
            else INFO + ["{t}/m.npz"])
    setup = npz_edit("m.npz", edit)
    if "(pose)" in name:
        setup = chain(setup, writer("pose.json", {"pose": [ZEROS48]}))
    case("npz model: indices, shapes, values", name, argv, setup=setup)
case("npz model: indices, shapes, values", "regressor index past the vertices (wrist)",
     ["model", "wrist", "{t}/m.npz", "--out", "{t}/w.npz"], setup=npz_edit("m.npz", _oob_indices))
case("npz model: indices, shapes, values", "regressor index past the vertices (render)",
     ["render", "{t}/m.npz", "--out", "{t}/out", "--size", "32"], setup=npz_edit("m.npz", _oob_indices))
case("npz model: indices, shapes, values", "declared shape 10^6 x 10^6", INFO + ["{t}/m.npz"],
     setup=npz_member("m.npz", "v_template", npy_bytes((10 ** 6, 10 ** 6))))
case("npz model: indices, shapes, values", "declared shape 10^5 x 3 x 135, little data", INFO + ["{t}/m.npz"],
     setup=npz_member("m.npz", "posedirs", npy_bytes((10 ** 5, 3, 135))))
case("npz model: indices, shapes, values", "declared shape with 10^30", INFO + ["{t}/m.npz"],
     setup=npz_member("m.npz", "weights", npy_bytes((10 ** 30, 16))))
case("npz model: indices, shapes, values", "object dtype member", INFO + ["{t}/m.npz"],
     setup=npz_member("m.npz", "faces", npy_bytes((3,), "|O")))
case("npz model: indices, shapes, values", "header not a dict", INFO + ["{t}/m.npz"],
     setup=npz_member("m.npz", "faces", b"\x93NUMPY\x01\x00\x10\x00[1, 2, 3]      \n"))
case("npz model: indices, shapes, values", "header with a deep literal", INFO + ["{t}/m.npz"],
     setup=npz_member("m.npz", "faces", b"\x93NUMPY\x02\x00" + struct.pack("<I", 60011)
                      + ("(" * 30000 + ")" * 30000 + "    \n").encode()))
case("npz model: indices, shapes, values", "zip bomb: 2 GB of zeros", INFO + ["{t}/m.npz"],
     setup=lambda t, fx: _zip_bomb(t / "m.npz", fx), timeout=120)


def _zip_bomb(path: Path, fx: Path) -> None:
    arrays = model_arrays(fx)
    path.parent.mkdir(parents=True, exist_ok=True)
    n = 2 * 1024 ** 3 // 8 // 3
    header = npy_bytes((n, 3), payload=b"")
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for k, v in arrays.items():
            if k != "v_template":
                buf = io.BytesIO()
                np.save(buf, v)
                z.writestr(f"{k}.npy", buf.getvalue())
        with z.open("v_template.npy", "w", force_zip64=True) as f:
            f.write(header)
            block = b"\0" * (1 << 24)
            left = n * 3 * 8
            while left > 0:
                f.write(block[: min(left, len(block))])
                left -= len(block)


# ---------------------------------------------------------------- npz: metadata fields
NPZ_META = {
    "format an int": set_("format", np.array(7)),
    "format an array of two": set_("format", np.array(["darthand-model", "x"])),
    "format bytes": set_("format", np.array(b"darthand-model")),
    "format_version a string": set_("format_version", np.array("one")),
    "format_version 1.5": set_("format_version", np.array(1.5)),
    "format_version 1e300": set_("format_version", np.array(1e300)),
    "format_version NaN": set_("format_version", np.array(np.nan)),
    "format_version an array": set_("format_version", np.array([1, 2])),
    "format_version missing": lambda a: a.pop("format_version"),
    "side an array": set_("side", np.array(["right", "left"])),
    "side an int": set_("side", np.array(3)),
    "side 'up'": set_("side", np.array("up")),
    "meta_json a list": set_("meta_json", np.array("[1, 2]")),
    "meta_json a string": set_("meta_json", np.array('"hello"')),
    "meta_json not JSON": set_("meta_json", np.array("{nope")),
    "meta_json 100000 deep": set_("meta_json", np.array(deep(100_000, "{}"))),
    "meta_json wrist a list": set_("meta_json", np.array(json.dumps({"wrist": [1, 2]}))),
    "meta_json fixes a number": set_("meta_json", np.array(json.dumps({"fixes": 5}))),
    "meta_json int of 5000 digits": set_("meta_json", np.array('{"a": ' + "9" * 5000 + "}")),
    "meta_json NaN": set_("meta_json", np.array('{"a": NaN}')),
    "meta_json an array of strings": set_("meta_json", np.array(["{}", "{}"])),
    "required field missing (weights)": lambda a: a.pop("weights"),
}
for name, edit in NPZ_META.items():
    case("npz model: metadata fields", name, INFO + ["{t}/m.npz"], setup=npz_edit("m.npz", edit))
case("npz model: metadata fields", "not a zip", INFO + ["{t}/m.npz"], setup=writer("m.npz", b"hello"))
case("npz model: metadata fields", "truncated zip", INFO + ["{t}/m.npz"],
     setup=lambda t, fx: data(t / "m.npz", (fx / "model" / "right.npz").read_bytes()[:50_000]))
case("npz model: metadata fields", "a .npy, not an .npz", INFO + ["{t}/m.npz"],
     setup=lambda t, fx: np.save(t / "m.npy", np.zeros(3)) or os.rename(t / "m.npy", t / "m.npz"))
case("npz model: metadata fields", "meta wrist broken (model pose)",
     ["model", "pose", "{t}/m.npz", "--out", "{t}/p.npz", "--pose", "{t}/pose.json"],
     setup=chain(npz_edit("m.npz", set_("meta_json", np.array(json.dumps({"wrist": "x", "uv_atlas": 3})))),
                 writer("pose.json", {"pose": [ZEROS48]})))

# ---------------------------------------------------------------- model files that are not regular files
case("model files: FIFO, directory, device", "npz is a FIFO", INFO + ["{t}/m.npz"], setup=fifo_at("m.npz"),
     timeout=30)
case("model files: FIFO, directory, device", "pkl is a FIFO", INFO + ["{t}/m.pkl"], setup=fifo_at("m.pkl"),
     timeout=30)
case("model files: FIFO, directory, device", "npz is a directory", INFO + ["{t}/m.npz"],
     setup=lambda t, fx: (t / "m.npz").mkdir(parents=True))
case("model files: FIFO, directory, device", "pkl is a directory", INFO + ["{t}/m.pkl"],
     setup=lambda t, fx: (t / "m.pkl").mkdir(parents=True))
case("model files: FIFO, directory, device", "pkl links to /dev/zero", INFO + ["{t}/m.pkl"],
     setup=lambda t, fx: symlink(t / "m.pkl", "/dev/zero"), timeout=30)
case("model files: FIFO, directory, device", "npz links to /dev/zero", INFO + ["{t}/m.npz"],
     setup=lambda t, fx: symlink(t / "m.npz", "/dev/zero"), timeout=30)
case("model files: FIFO, directory, device", "npz links to /dev/urandom", INFO + ["{t}/m.npz"],
     setup=lambda t, fx: symlink(t / "m.npz", "/dev/urandom"), timeout=30)
case("model files: FIFO, directory, device", "FIFO model for export usd",
     ["export", "usd", "{t}/m.npz", "--out", "{t}/usd"], setup=fifo_at("m.npz"), timeout=30)
case("model files: FIFO, directory, device", "FIFO model for render", ["render", "{t}/m.npz", "--out", "{t}/o"],
     setup=fifo_at("m.npz"), timeout=30)
case("model files: FIFO, directory, device", "FIFO model for textures build",
     ["textures", "build", "{t}/m.npz", "--out", "{t}/tex", "--res", "64"], setup=fifo_at("m.npz"), timeout=30)
case("model files: FIFO, directory, device", "FIFO model for accessories build",
     ["accessories", "build", "{t}/m.npz", "--out", "{t}/acc"], setup=fifo_at("m.npz"), timeout=30)

# ---------------------------------------------------------------- pose files
POSE_FILES = {
    "1,000 nested brackets": deep(1000),
    "100,000 nested brackets": deep(100_000),
    "1,000 nested objects": deep(1000, "0", "dict"),
    "values 1e300": json.dumps({"pose": [[1e300] * 48]}),
    "values 1e308 (Infinity after maths)": json.dumps({"pose": [[1.7e308] * 48]}),
    "NaN token": '{"pose": [[' + ", ".join(["NaN"] + ["0"] * 47) + "]]}",
    "Infinity token": '{"pose": [[' + ", ".join(["Infinity"] + ["0"] * 47) + "]]}",
    "1e999 (parses as inf)": '{"pose": [[' + ", ".join(["1e999"] + ["0"] * 47) + "]]}",
    "int of 400 digits": '{"pose": [[' + ", ".join(["9" * 400] + ["0"] * 47) + "]]}",
    "int of 5000 digits": '{"pose": [[' + ", ".join(["9" * 5000] + ["0"] * 47) + "]]}",
    "betas NaN": '{"pose": [' + json.dumps(ZEROS48) + '], "betas": [NaN]}',
    "betas 1e300": json.dumps({"pose": [ZEROS48], "betas": [1e300] * 10}),
    "betas int of 400 digits": '{"pose": [' + json.dumps(ZEROS48) + '], "betas": [' + "9" * 400 + "]}",
    "betas 10,000 values": json.dumps({"pose": [ZEROS48], "betas": [0.0] * 10_000}),
    "strings in the pose": json.dumps({"pose": [["x"] * 48]}),
    "flat_hand_mean a string": json.dumps({"pose": [ZEROS48], "flat_hand_mean": "yes"}),
    "a bare number": "5",
    "invalid UTF-8": b'{"pose": [\xff\xfe]}',
    "a UTF-16 file": '{"pose": [[0]]}'.encode("utf-16"),
    "empty file": "",
    "200,000 poses": '{"pose": [' + ",".join(["[" + ",".join(["0"] * 48) + "]"] * 200_000) + "]}",
}
for name, content in POSE_FILES.items():
    case("pose files", f"model pose: {name}", POSE + ["{t}/pose.json"], setup=writer("pose.json", content),
         timeout=120)
for name in ("1,000 nested brackets", "values 1e300", "values 1e308 (Infinity after maths)", "NaN token",
             "int of 400 digits", "int of 5000 digits", "betas NaN"):
    case("pose files", f"render: {name}", RENDER + ["--pose", "{t}/pose.json"],
         setup=writer("pose.json", POSE_FILES[name]))
case("pose files", "pose file is a FIFO", POSE + ["{t}/pose.json"], setup=fifo_at("pose.json"), timeout=30)
case("pose files", "render --pose a FIFO", RENDER + ["--pose", "{t}/pose.json"], setup=fifo_at("pose.json"),
     timeout=30)
case("pose files", "render --pose 48 x 1e300", RENDER + ["--pose", ",".join(["1e300"] * 48)])
case("pose files", "render --pose 48 x nan", RENDER + ["--pose", ",".join(["nan"] * 48)])
case("pose files", "render --pose 48 x inf", RENDER + ["--pose", ",".join(["inf"] * 48)])
case("pose files", "render --pose-index -1", RENDER + ["--pose", "{t}/pose.json", "--pose-index", "-1"],
     setup=writer("pose.json", {"pose": [ZEROS48, ZEROS48]}))
case("pose files", "render --pose-index 10^30", RENDER + ["--pose", "{t}/pose.json", "--pose-index", "1" + "0" * 30],
     setup=writer("pose.json", {"pose": [ZEROS48, ZEROS48]}))

# ---------------------------------------------------------------- lights files
LIGHT = {"type": "directional", "direction": [0, 0, 1], "intensity": 1.0}


def lights(**over) -> str:
    d = {"ambient": {"intensity": 0.2}, "lights": [dict(LIGHT, **over)]}
    return json.dumps(d)


LIGHT_FILES = {
    "intensity NaN": lights(intensity=float("nan")),
    "intensity Infinity": lights(intensity=float("inf")),
    "intensity 1e999": lights().replace('"intensity": 1.0', '"intensity": 1e999'),
    "intensity 1e300": lights(intensity=1e300),
    "intensity 1e39 (float32 overflow)": lights(intensity=1e39),
    "intensity int of 400 digits": lights().replace('"intensity": 1.0', '"intensity": ' + "9" * 400),
    "ambient NaN": json.dumps({"ambient": {"intensity": float("nan")}, "lights": []}),
    "ambient colour Infinity": json.dumps({"ambient": {"intensity": 1, "color": [float("inf"), 1, 1]}}),
    "colour NaN": lights(color=[float("nan"), 1, 1]),
    "direction NaN": lights(direction=[float("nan"), 0, 1]),
    "direction 1e-320 (subnormal)": lights(direction=[1e-320, 0, 0]),
    "direction 1e300": lights(direction=[1e300, 1e300, 1e300]),
    "point at NaN": json.dumps({"lights": [{"type": "point", "position": [float("nan"), 0, 0]}]}),
    "point at the hand centre": json.dumps({"lights": [{"type": "point", "position": [0, 0, 0], "intensity": 1}]}),
    "1,000 nested brackets": deep(1000),
    "100,000 nested objects": deep(100_000, "0", "dict"),
    "lights not a list": json.dumps({"lights": {"a": 1}}),
    "empty file": "",
}
def labels_are_strict_json(t: Path, fx: Path) -> str | None:
    """After a render that succeeded: labels.json is JSON (no NaN or Infinity) and the image was written."""
    labels = t / "out" / "labels.json"
    if not labels.is_file() or not (t / "out" / "image.png").is_file():
        return "no labels.json or image.png written"
    try:
        json.loads(labels.read_text(), parse_constant=lambda name: (_ for _ in ()).throw(ValueError(name)))
    except ValueError as e:
        return f"labels.json is not strict JSON ({e})"
    return None


for name, content in LIGHT_FILES.items():
    legal = name == "point at the hand centre"     # odd but valid: it must render, with valid labels
    case("lights files", name, RENDER + ["--lights", "{t}/lights.json"], setup=writer("lights.json", content),
         expect=(0,) if legal else (2,), check=labels_are_strict_json if legal else None)
case("lights files", "lights file is a FIFO", RENDER + ["--lights", "{t}/lights.json"], setup=fifo_at("lights.json"),
     timeout=30)

# ---------------------------------------------------------------- camera files
CAMERA_FILES = {
    "fov NaN": '{"fov_deg": NaN, "view": "dorsal"}',
    "fov int of 400 digits": '{"fov_deg": ' + "9" * 400 + ', "view": "dorsal"}',
    "focal NaN": '{"focal_px": NaN, "view": "dorsal"}',
    "width 0": json.dumps({"width": 0, "view": "dorsal"}),
    "width -5": json.dumps({"width": -5, "view": "dorsal"}),
    "width 10^30": json.dumps({"width": 10 ** 30, "height": 10, "view": "dorsal"}),
    "width 100000 x 100000": json.dumps({"width": 100_000, "height": 100_000, "view": "dorsal"}),
    "width 1.5": json.dumps({"width": 1.5, "view": "dorsal"}),
    "K with NaN": '{"K": [[NaN, 0, 24], [0, 50, 24], [0, 0, 1]], "R": [[1,0,0],[0,1,0],[0,0,1]], "t": [0,0,1]}',
    "t 1e300": json.dumps({"K": [[50, 0, 24], [0, 50, 24], [0, 0, 1]], "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                           "t": [0, 0, 1e300]}),
    "R not a rotation": json.dumps({"K": [[50, 0, 24], [0, 50, 24], [0, 0, 1]], "R": [[2, 0, 0], [0, 1, 0],
                                                                                       [0, 0, 1]], "t": [0, 0, 1]}),
    "look_at eye NaN": '{"look_at": {"eye": [NaN, 0, 0], "target": [0, 0, 0]}}',
    "look_at eye 1e300": json.dumps({"look_at": {"eye": [1e300, 0, 0], "target": [0, 0, 0]}}),
    "view vector NaN": '{"view": [NaN, 0, 1]}',
    "distance NaN": '{"view": "dorsal", "distance": NaN}',
    "distance -1": json.dumps({"view": "dorsal", "distance": -1}),
    "distance 0": json.dumps({"view": "dorsal", "distance": 0}),
    "margin 0.5": json.dumps({"view": "dorsal", "margin": 0.5}),
    "margin NaN": '{"view": "dorsal", "margin": NaN}',
    "roll NaN": '{"view": "dorsal", "roll_deg": NaN}',
    "roll 1e300": json.dumps({"view": "dorsal", "roll_deg": 1e300}),
    "1,000 nested brackets": deep(1000),
    "100,000 nested objects": deep(100_000, "0", "dict"),
}
for name, content in CAMERA_FILES.items():
    case("camera files", name, RENDER + ["--camera", "{t}/camera.json"], setup=writer("camera.json", content))
case("camera files", "camera file is a FIFO", RENDER + ["--camera", "{t}/camera.json"],
     setup=fifo_at("camera.json"), timeout=30)

# ---------------------------------------------------------------- jobs files (their JSON; the fields are the dataset's)
DATASET = ["render-dataset", "{fx}/model/right.npz", "--textures", "{fx}/tex", "--accessories", "{fx}/acc", "--out",
           "{t}/ds", "--size", "32", "--processes", "1", "--jobs", "{t}/jobs.json"]
case("jobs files (JSON only)", "1,000 nested brackets", DATASET, setup=writer("jobs.json", deep(1000)))
case("jobs files (JSON only)", "100,000 nested objects", DATASET, setup=writer("jobs.json", deep(100_000, "0", "dict")))
case("jobs files (JSON only)", "int of 5000 digits", DATASET,
     setup=writer("jobs.json", '{"frames": ' + "9" * 5000 + "}"))
case("jobs files (JSON only)", "invalid UTF-8", DATASET, setup=writer("jobs.json", b"\xff\xfe{"))
case("jobs files (JSON only)", "jobs file is a FIFO", DATASET, setup=fifo_at("jobs.json"), timeout=30)


# ---------------------------------------------------------------- catalogues
def catalogue(kind: str, fn):
    """setup: a copy of the fixture catalogue folder ({t}/tex or {t}/acc) with fn(doc, folder) applied."""
    def setup(t: Path, fx: Path) -> None:
        folder = t / kind
        shutil.copytree(fx / kind, folder)
        path = folder / "catalog.json"
        doc = json.loads(path.read_text())
        out = fn(doc, folder, t)
        path.write_text(out if isinstance(out, str) else json.dumps(doc))
    return setup


RENDER_CAT = ["render", "{fx}/model/right.npz", "--textures", "{t}/tex", "--accessories", "{t}/acc", "--out",
              "{t}/out", "--size", "48"]


def both_catalogues(kind: str, fn):
    other = "acc" if kind == "tex" else "tex"
    return chain(catalogue(kind, fn), lambda t, fx: shutil.copytree(fx / other, t / other))


def _set_first(key, value):
    def fn(doc, folder, t):
        entries = doc.get("entries") or doc.get("accessories")
        entries[0][key] = value if not isinstance(value, str) else value.replace("{t}", str(t))
    return fn


def _set_files(key, value):
    def fn(doc, folder, t):
        entries = doc.get("entries") or doc.get("accessories")
        entries[0]["files"][key] = value.replace("{t}", str(t))
        (t / "outside").mkdir(exist_ok=True)
        shutil.copy(folder / "brown_moles_00.png" if (folder / "brown_moles_00.png").exists()
                    else next(folder.glob("*.png")), t / "outside" / "secret.png")
        shutil.copy(next(folder.glob("*.npz")), t / "outside" / "secret.npz")
    return fn


CATALOGUE_CASES = {
    ("tex", "1,000 nested brackets"): lambda doc, f, t: deep(1000),
    ("tex", "100,000 nested objects"): lambda doc, f, t: deep(100_000, "0", "dict"),
    ("tex", "entries not a list"): lambda doc, f, t: doc.__setitem__("entries", {"a": 1}),
    ("tex", "resolution int of 400 digits"): lambda doc, f, t: json.dumps(doc).replace(
        '"resolution": 64', '"resolution": ' + "9" * 400),
    ("tex", "albedo file outside (absolute)"): _set_files("albedo", "{t}/outside/secret.png"),
    ("tex", "albedo file outside (../)"): _set_files("albedo", "../outside/secret.png"),
    ("tex", "albedo file a FIFO"): lambda doc, f, t: (os.unlink(f / "brown_moles_00.png"),
                                                      os.mkfifo(f / "brown_moles_00.png")),
    ("tex", "albedo truncated PNG"): lambda doc, f, t: (f / "brown_moles_00.png").write_bytes(
        (f / "brown_moles_00.png").read_bytes()[:200]),
    ("tex", "offset NaN"): _set_first("offset", float("nan")),
    ("acc", "1,000 nested brackets"): lambda doc, f, t: deep(1000),
    ("acc", "accessories not a list"): lambda doc, f, t: doc.__setitem__("accessories", 5),
    ("acc", "mesh file outside (absolute)"): lambda doc, f, t: _acc_outside(doc, f, t, absolute=True),
    ("acc", "mesh file outside (../)"): lambda doc, f, t: _acc_outside(doc, f, t, absolute=False),
    ("acc", "mesh npz a FIFO"): lambda doc, f, t: (os.unlink(f / "ring_01_court_gold.npz"),
                                                   os.mkfifo(f / "ring_01_court_gold.npz")),
    ("acc", "mesh npz with faces out of range"): lambda doc, f, t: _acc_faces(f),
    ("acc", "parent_joint 99"): _set_first("parent_joint", 99),
}


def _acc_outside(doc, folder, t, absolute: bool):
    acc = doc["accessories"][0]
    (t / "outside").mkdir(exist_ok=True)
    for key, name in list(acc.get("files", {}).items()):
        if isinstance(name, str) and name.endswith(".npz"):
            shutil.copy(folder / name, t / "outside" / "secret.npz")
            acc["files"][key] = str(t / "outside" / "secret.npz") if absolute else "../outside/secret.npz"


def _acc_faces(folder: Path) -> None:
    p = folder / "ring_01_court_gold.npz"
    with np.load(p) as z:
        a = {k: z[k] for k in z.files}
    for k in a:
        if "faces" in k:
            a[k] = a[k] + 10 ** 7
    np.savez(p, **a)


for (kind, name), fn in CATALOGUE_CASES.items():
    watch = ("{t}/outside/secret.png", "{t}/outside/secret.npz") if "outside" in name else ()
    extra = ["--accessory", "ring_01_court_gold"] if kind == "acc" else ["--texture", "brown_moles_00"]
    case("catalogues (texture, accessory)", f"{'texture' if kind == 'tex' else 'accessory'}: {name}",
         RENDER_CAT + extra, setup=both_catalogues(kind, fn), watch=watch, timeout=30)
    if kind == "tex" and ("outside" in name or "FIFO" in name or "nested" in name):
        case("catalogues (texture, accessory)", f"texture (export usd): {name}",
             ["export", "usd", "{fx}/model/right.npz", "--out", "{t}/usd", "--textures", "{t}/tex"],
             setup=both_catalogues(kind, fn), watch=watch, timeout=30)
case("catalogues (texture, accessory)", "texture spec: 1,000 nested brackets",
     ["textures", "build", "{fx}/model/right.npz", "--out", "{t}/tex2", "--spec", "{t}/spec.json", "--res", "64"],
     setup=writer("spec.json", deep(1000)))
case("catalogues (texture, accessory)", "accessory spec: 1,000 nested brackets",
     ["accessories", "build", "{fx}/model/right.npz", "--out", "{t}/acc2", "--spec", "{t}/spec.json"],
     setup=writer("spec.json", deep(1000)))
case("catalogues (texture, accessory)", "texture spec is a FIFO",
     ["textures", "build", "{fx}/model/right.npz", "--out", "{t}/tex2", "--spec", "{t}/spec.json", "--res", "64"],
     setup=fifo_at("spec.json"), timeout=30)


# ---------------------------------------------------------------- asset.json
def asset_json(content):
    def fn(t: Path, pkg: Path) -> None:
        p = pkg / "asset.json"
        if content == "FIFO":
            p.unlink()
            os.mkfifo(p)
        else:
            p.write_text(content if isinstance(content, str) else json.dumps(content))
    return fn


ASSET_JSON = {
    "1,000 nested brackets": deep(1000),
    "100,000 nested objects": deep(100_000, "0", "dict"),
    "a list": "[1, 2]",
    "options a list": {"interface": "right.usda", "options": [1, 2], "side": "right"},
    "side a number": {"interface": "right.usda", "side": 5},
    "interface outside": {"interface": "../../outside/secret.usda"},
    "interface a number": {"interface": 5},
    "model.tip_ids huge": {"interface": "right.usda", "side": "right", "model": {"tip_ids": [10 ** 30] * 5}},
    "invalid UTF-8": "\udcff",
    "FIFO": "FIFO",
}
for name, content in ASSET_JSON.items():
    setup = usd_edit(asset_json(content) if content != "\udcff" else
                     lambda t, pkg: (pkg / "asset.json").write_bytes(b"\xff\xfe{"))
    watch = ("{t}/outside/secret.usda",) if "outside" in name else ()
    case("asset.json", f"validate: {name}", VALIDATE + ["{t}/pkg/right"], setup=setup, expect=(1, 2), watch=watch,
         timeout=30)
    case("asset.json", f"render: {name}", RENDER_USD, setup=setup, watch=watch, timeout=30)
    if name in ("1,000 nested brackets", "interface outside", "FIFO", "a list"):
        case("asset.json", f"export usdz: {name}", ["export", "usdz", "{t}/pkg/right", "--out", "{t}/x.usdz"],
             setup=setup, watch=watch, timeout=30)

# ---------------------------------------------------------------- USD packages
OUT = ("{t}/outside/secret.usda", "{t}/outside/payload.usdc", "{t}/outside/secret.png")


def _texture_file(value: str):
    def fn(t: Path, pkg: Path) -> None:
        edit_text(pkg / "texture" / "brown_moles_00.usda", "@./brown_moles_00/brown_moles_00.png@",
                  f"@{value.replace('{t}', str(t))}@")
    return fn


def _texture_link(t: Path, pkg: Path) -> None:
    p = pkg / "texture" / "brown_moles_00" / "brown_moles_00.png"
    p.unlink()
    os.symlink(t / "outside" / "secret.png", p)


def _texture_fifo(t: Path, pkg: Path) -> None:
    p = pkg / "texture" / "brown_moles_00" / "brown_moles_00.png"
    p.unlink()
    os.mkfifo(p)


def _reference_outside(t: Path, pkg: Path) -> None:
    edit_text(pkg / "right.usda", "@./texture/light_tattoos_07.usda@", "@../../outside/secret.usda@")


def _payload_outside(t: Path, pkg: Path) -> None:
    edit_text(pkg / "right.usda", "@./payload.usdc@", "@../../outside/payload.usdc@")


def _payload_fifo(t: Path, pkg: Path) -> None:
    (pkg / "payload.usdc").unlink()
    os.mkfifo(pkg / "payload.usdc")


def _sublayer_fifo(t: Path, pkg: Path) -> None:
    os.mkfifo(pkg / "extra.usda")
    add_sublayer("./extra.usda")(t, pkg)


def _payload_link(t: Path, pkg: Path) -> None:
    (pkg / "payload.usdc").unlink()
    os.symlink(t / "outside" / "payload.usdc", pkg / "payload.usdc")


def _interface_fifo(t: Path, pkg: Path) -> None:
    (pkg / "right.usda").unlink()
    os.mkfifo(pkg / "right.usda")


def _sublayer_dir(t: Path, pkg: Path) -> None:
    add_sublayer("../../outside")(t, pkg)


def _usdz_outside(t: Path, pkg: Path) -> None:
    from pxr import Sdf, UsdUtils  # noqa: F401

    layer = Sdf.Layer.CreateNew(str(t / "evil" / "evil.usda"))
    layer.subLayerPaths.append(str(t / "outside" / "secret.usda"))
    prim = Sdf.CreatePrimInLayer(layer, "/Hand")
    prim.specifier = Sdf.SpecifierDef
    prim.referenceList.Prepend(Sdf.Reference(str(t / "outside" / "secret.usda")))
    layer.defaultPrim = "Hand"
    layer.Save()
    with zipfile.ZipFile(t / "evil.usdz", "w", zipfile.ZIP_STORED) as z:
        z.write(t / "evil" / "evil.usda", "evil.usda")


USD_CASES = {
    "sublayer outside (../)": add_sublayer("../../outside/secret.usda"),
    "sublayer outside (absolute)": add_sublayer("{t}/outside/secret.usda"),
    "sublayer a FIFO": _sublayer_fifo,
    "sublayer a folder": _sublayer_dir,
    "variant reference outside": _reference_outside,
    "payload outside": _payload_outside,
    "payload a link to outside": _payload_link,
    "payload a FIFO": _payload_fifo,
    "texture file outside (absolute)": _texture_file("{t}/outside/secret.png"),
    "texture file outside (../)": _texture_file("../../../outside/secret.png"),
    "texture file a link to outside": _texture_link,
    "texture file a FIFO": _texture_fifo,
    "interface layer a FIFO": _interface_fifo,
}
for name, fn in USD_CASES.items():
    target = ["{t}/pkg/right/right.usda"] if "interface" in name else ["{t}/pkg/right"]
    case("USD packages: outside files, non-regular files", f"validate: {name}", VALIDATE + target,
         setup=usd_edit(fn), expect=(1, 2), watch=OUT, timeout=30)
    argv = RENDER_USD + (["--texture", "light_tattoos_07"] if "variant" in name else [])
    case("USD packages: outside files, non-regular files", f"render: {name}", argv, setup=usd_edit(fn), watch=OUT,
         timeout=30)
    if "texture" in name or "sublayer outside" in name:
        case("USD packages: outside files, non-regular files", f"export usdz: {name}",
             ["export", "usdz", "{t}/pkg/right", "--out", "{t}/x.usdz"], setup=usd_edit(fn), watch=OUT, timeout=30)
case("USD packages: outside files, non-regular files", "validate: usdz referencing outside",
     VALIDATE + ["{t}/evil.usdz"], setup=usd_edit(lambda t, pkg: _usdz_outside(t, pkg)), expect=(1, 2), watch=OUT,
     timeout=30)

# ---------------------------------------------------------------- glTF packages
GOUT = ("{t}/outside/secret.bin", "{t}/outside/secret.png")


def _gltf_fifo(what: str):
    def fn(t, pkg, doc):
        name = "fifo.bin" if what == "buffer" else "textures/fifo.png"
        os.mkfifo(pkg / name)
        doc["buffers" if what == "buffer" else "images"][0]["uri"] = name
    return fn


def _gltf_link(what: str):
    def fn(t, pkg, doc):
        name = "link.bin" if what == "buffer" else "textures/link.png"
        os.symlink(t / "outside" / ("secret.bin" if what == "buffer" else "secret.png"), pkg / name)
        doc["buffers" if what == "buffer" else "images"][0]["uri"] = name
    return fn


GLTF_CASES = {
    "buffer URI absolute": buffer_uri("{t}/outside/secret.bin"),
    "buffer URI ../": buffer_uri("../outside/secret.bin"),
    "buffer URI file://": buffer_uri("file://{t}/outside/secret.bin"),
    "buffer URI percent-encoded ../": buffer_uri("..%2Foutside%2Fsecret.bin"),
    "buffer URI a link to outside": _gltf_link("buffer"),
    "buffer URI a FIFO": _gltf_fifo("buffer"),
    "buffer URI a folder": buffer_uri("textures"),
    "image URI absolute": image_uri("{t}/outside/secret.png"),
    "image URI ../": image_uri("../outside/secret.png"),
    "image URI percent-encoded absolute": image_uri("%2F" + "{t}/outside/secret.png".lstrip("/").replace("/", "%2F")),
    "image URI a link to outside": _gltf_link("image"),
    "image URI a FIFO": _gltf_fifo("image"),
    "JSON 1,000 nested brackets": lambda t, pkg, doc: doc.setdefault("extras", json.loads(deep(900))),
}
for name, fn in GLTF_CASES.items():
    case("glTF packages: outside files, non-regular files", f"validate: {name}", VALIDATE + ["{t}/pkg/right.gltf"],
         setup=gltf_edit(fn), expect=(1, 2), watch=GOUT, timeout=60)
case("glTF packages: outside files, non-regular files", "validate: JSON 100,000 nested brackets",
     VALIDATE + ["{t}/pkg/right.gltf"], setup=lambda t, fx: (gltf_pkg(t, fx), text(t / "pkg" / "right.gltf",
                                                                                   deep(100_000))),
     expect=(1, 2), timeout=60)
case("glTF packages: outside files, non-regular files", "validate: .gltf file is a FIFO",
     VALIDATE + ["{t}/pkg/right.gltf"],
     setup=lambda t, fx: (gltf_pkg(t, fx), os.unlink(t / "pkg" / "right.gltf"), os.mkfifo(t / "pkg" / "right.gltf")),
     expect=(1, 2), timeout=30)
case("glTF packages: outside files, non-regular files", "validate: .glb in a folder is a FIFO", VALIDATE + ["{t}/d"],
     setup=fifo_at("d/x.glb"), expect=(1, 2), timeout=30)

# ---------------------------------------------------------------- numeric options
WRIST = ["model", "wrist", "open", "--out", "{t}/w.npz"]
TEX = ["textures", "build", "{fx}/model/right.npz", "--out", "{t}/tex", "--ids", "brown_moles_00", "--no-tx",
       "--no-sheet", "--jobs", "1"]
ACC = ["accessories", "build", "{fx}/model/right.npz", "--out", "{t}/acc", "--ids", "ring_01_court_gold",
       "--no-sheet"]
USD = ["export", "usd", "{fx}/model/right.npz", "--out", "{t}/usd", "--textures", "{fx}/tex"]
GLTF = ["export", "gltf", "{fx}/model/right.npz", "--out", "{t}/x.glb", "--textures", "{fx}/tex"]
BIG = "1" + "0" * 30
NUMERIC = [
    (RENDER, "--skin-tone-offset", ["nan", "inf", "-inf", "1e300", "5"]),
    (RENDER, "--size", ["0", "-1", "100000", BIG]),
    (RENDER, "--width", ["0", "-7"]),
    (RENDER, "--height", ["2000000"]),
    (RENDER, "--threads", ["-3", "0", "100000"]),
    (["render-checks", "--build", "{fx}", "--sides", "right", "--out", "{t}/checks"], "--size", ["0", "-1", "100000"]),
    (WRIST, "--rings", ["0", "-1", "1000000", BIG]),
    (WRIST, "--length", ["nan", "inf", "-0.1", "0", "1e300"]),
    (WRIST, "--taper", ["nan", "-1", "0", "inf"]),
    (WRIST, "--anchor", ["-5", "1000000000", BIG]),
    (["model", "build", "{fx}/MANO_RIGHT.pkl", "--out-dir", "{t}/m"], "--atlas-res", ["0", "-1", "1000000"]),
    (TEX, "--res", ["0", "3", "-1", "1000000", BIG]),
    (TEX, "--jobs", ["0", "-3", "100000"]),
    (ACC, "--poses", ["-1", "1000000000"]),
    (ACC, "--tolerance", ["nan", "-1", "inf"]),
    (USD, "--texture-size", ["0", "-1", "1000000000"]),
    (USD, "--correctives", ["pca:0", "pca:nan", "pca:" + BIG, "pca:-3"]),
    (GLTF, "--clip-keys", ["0", "-1", "1000000000"]),
    (GLTF, "--texture-size", ["0", "-1"]),
    (["template", "gestures", "open", "--out-dir", "{t}/g"], "--max-between-fingers", ["-1", "nan"]),
]
for base, option, values in NUMERIC:
    command = " ".join(a for a in base[:2] if not a.startswith("{"))
    for v in values:
        case("numeric options", f"{command} {option} {v if len(v) < 12 else v[:4] + '...'}", base + [f"{option}={v}"],
             timeout=90)

# ---------------------------------------------------------------- output paths
AFILE = writer("afile", "x")
OUTPUTS = [
    ("render --out a file", RENDER[:-4] + ["--out", "{t}/afile", "--size", "48"]),
    ("render --out under a file", RENDER[:-4] + ["--out", "{t}/afile/sub", "--size", "48"]),
    ("render --out in /proc", RENDER[:-4] + ["--out", "/proc/darthand-probe", "--size", "48"]),
    ("model pose --out a folder", ["model", "pose", "open", "--pose", "{t}/pose.json", "--out", "{t}"]),
    ("model pose --out under a file", ["model", "pose", "open", "--pose", "{t}/pose.json", "--out", "{t}/afile/p.npz"]),
    ("model wrist --out in /proc", ["model", "wrist", "open", "--out", "/proc/darthand-probe.npz"]),
    ("model build --out-dir a file", ["model", "build", "open", "--out-dir", "{t}/afile"]),
    ("textures build --out a file", TEX[:3] + ["--out", "{t}/afile"] + TEX[5:]),
    ("accessories build --out under a file", ACC[:3] + ["--out", "{t}/afile/acc"] + ACC[5:]),
    ("export usd --out under a file", USD[:3] + ["--out", "{t}/afile/usd"] + USD[5:]),
    ("export usd --out in /proc", USD[:3] + ["--out", "/proc/darthand-probe"] + USD[5:]),
    ("export gltf --out under a file", GLTF[:3] + ["--out", "{t}/afile/x.glb"] + GLTF[5:]),
    ("export gltf --out a folder", GLTF[:3] + ["--out", "{t}/adir.glb"] + GLTF[5:]),
    ("export usdz --out under a file", ["export", "usdz", "{fx}/usd/right", "--out", "{t}/afile/x.usdz"]),
    ("validate --out under a file", ["validate", "{fx}/glb/right.glb", "--out", "{t}/afile/r.json"]),
    ("template gestures --out-dir in /proc", ["template", "gestures", "open", "--out-dir", "/proc/darthand-probe"]),
    ("render-dataset --out a file", DATASET[:-2] + ["--count", "1", "--out", "{t}/afile"]),
    ("manifest --build a file", ["manifest", "--build", "{t}/afile"]),
    ("render --background a FIFO", RENDER + ["--background", "{t}/bg.png"]),
    ("render --background a truncated PNG", RENDER + ["--background", "{t}/trunc.png"]),
    ("render --background links to /dev/zero", RENDER + ["--background", "{t}/zero.png"]),
]


def _outputs_setup(t: Path, fx: Path) -> None:
    AFILE(t, fx)
    (t / "adir.glb").mkdir()
    text(t / "pose.json", json.dumps({"pose": [ZEROS48]}))
    os.mkfifo(t / "bg.png")
    png = (fx / "tex" / "brown_moles_00.png").read_bytes()
    data(t / "trunc.png", png[: len(png) // 3])
    os.symlink("/dev/zero", t / "zero.png")


for name, argv in OUTPUTS:
    case("file-system errors", name, argv, setup=_outputs_setup, timeout=30)
