"""MANO-format pickle fixtures (the real MANO files are licensed and never in the repository).

`mano_like_model` is a realistic one: the open CC0 hand remeshed to MANO's budget (778 vertices, 1538 faces, a
16-vertex wrist loop), re-rigged and laid out as MANO's file is; `write_mano_like` pickles it as MANO_RIGHT.pkl /
MANO_LEFT.pkl. From the command line (to try `make assets MANO=...` by hand):

    .venv/bin/python tests/model/mano_fixture.py OUT_DIR [--thicken MM]

`write_mano_pkl` writes a HandModel the way the official MANO_RIGHT.pkl / MANO_LEFT.pkl are laid out: a protocol 2
pickle of a dict whose `shapedirs` is a chumpy `Ch` (optionally a `Select` over a wider `Ch`), whose J_regressor is
a scipy CSC matrix, kintree_table has 4294967295 for the root and `f` is uint32. By default the bytes look like
Python 2's: globals named `numpy.core.multiarray._reconstruct`, `scipy.sparse.csc.csc_matrix`, `chumpy.ch.Ch`,
`__builtin__.set`, and byte strings as BINSTRING (so they only load with encoding='latin1'). chumpy is not used:
the `Ch`/`Select` classes below only pretend to live in `chumpy.ch` / `chumpy.reordering` while pickling.

`malicious_pickle` builds pickles that run a command creating a marker file when loaded by plain `pickle.loads`.
"""

from __future__ import annotations

import contextlib
import functools
import io
import pickle
import struct
import sys
import types
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from darthand.model.hand_model import HandModel

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/: also when run as a script
from synthetic import tube_hand  # noqa: E402

ROOT_PARENT = 4294967295  # uint32(-1), as in the official files


class Ch:
    """Pickles like chumpy's Ch: NEWOBJ of chumpy.ch.Ch, then its __dict__ (chumpy drops _parents/_cache)."""

    def __init__(self, x):
        self.x = np.asarray(x)
        self._dirty_vars = {"x"}
        self._itr = None
        self._depends_on_deps = {}


class Select:
    """Pickles like chumpy.reordering.Select, what `Ch.__getitem__` returns: flat `idxs` into `a`, reshaped."""

    def __init__(self, a, idxs, preferred_shape):
        self.a = a
        self.idxs = np.asarray(idxs)
        self.preferred_shape = tuple(preferred_shape)
        self._dirty_vars = {"a"}
        self._itr = None


Ch.__module__, Ch.__qualname__ = "chumpy.ch", "Ch"
Select.__module__, Select.__qualname__ = "chumpy.reordering", "Select"


@contextlib.contextmanager
def fake_chumpy_modules():
    """Register `chumpy`, `chumpy.ch`, `chumpy.reordering` in sys.modules for the pickler; restore them after."""
    package = types.ModuleType("chumpy")
    ch_module = types.ModuleType("chumpy.ch")
    reordering = types.ModuleType("chumpy.reordering")
    ch_module.Ch, reordering.Select = Ch, Select
    package.ch, package.reordering = ch_module, reordering
    fakes = {"chumpy": package, "chumpy.ch": ch_module, "chumpy.reordering": reordering}
    saved = {name: sys.modules.get(name) for name in fakes}
    sys.modules.update(fakes)
    try:
        yield
    finally:
        for name, module in saved.items():
            if module is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = module


# Where Python-2-era numpy/scipy kept what modern versions pickle under new module names.
PY2_MODULES = {
    "numpy._core.multiarray": "numpy.core.multiarray",
    "numpy._core.numeric": "numpy.core.numeric",
    "scipy.sparse._csc": "scipy.sparse.csc",
    "scipy.sparse._csr": "scipy.sparse.csr",
}


class Py2StylePickler(pickle._Pickler):
    """The pure-Python pickler, made to write what Python 2 wrote: bytes and ASCII text as BINSTRING, and numpy/scipy
    globals under their old module names. (The C pickler cannot be changed this way, hence the private class.)"""

    dispatch = dict(pickle._Pickler.dispatch)

    def _save_binstring(self, data: bytes, obj) -> None:
        n = len(data)
        self.write((pickle.SHORT_BINSTRING + bytes([n]) if n < 256 else pickle.BINSTRING + struct.pack("<i", n)) + data)
        self.memoize(obj)

    def save_py2_str(self, obj: bytes) -> None:
        self._save_binstring(obj, obj)

    def save_py2_text(self, obj: str) -> None:
        if obj.isascii():
            self._save_binstring(obj.encode("ascii"), obj)
        else:
            pickle._Pickler.save_str(self, obj)

    dispatch[bytes] = save_py2_str
    dispatch[str] = save_py2_text

    def save_global(self, obj, name=None):
        module = getattr(obj, "__module__", None)
        if module in PY2_MODULES:
            name = name or obj.__qualname__
            self.write(pickle.GLOBAL + f"{PY2_MODULES[module]}\n{name}\n".encode("ascii"))
            self.memoize(obj)
        else:
            super().save_global(obj, name)


def dumps_like_mano(obj, protocol: int = 2, py2: bool = True) -> bytes:
    """Pickle `obj` (with fixture Ch/Select objects) as the official files are: Python 2 style at protocol 2."""
    with fake_chumpy_modules():
        if py2 and protocol in (1, 2):
            buf = io.BytesIO()
            Py2StylePickler(buf, protocol=protocol).dump(obj)
            return buf.getvalue()
        return pickle.dumps(obj, protocol=protocol)


def mirror_x(model: HandModel) -> HandModel:
    """The x-mirror of `model` (x -> -x), in closed form, to make left-hand fixtures.

    Vertices, shape directions and corrective offsets negate x; faces reverse winding; a pose feature
    (R_i - I)[a, b] becomes m_a m_b (R_i - I)[a, b] with m = (-1, 1, 1), and axis-angle poses become (x, -y, -z).
    """
    m = np.array([-1.0, 1.0, 1.0])
    feature_sign = np.tile((m[:, None] * m[None, :]).reshape(9), 15)  # (135,)
    v = model.v_template * m
    aa_sign = np.tile(np.array([1.0, -1.0, -1.0]), 15)
    return model.replace(
        v_template=v,
        faces=model.faces[:, ::-1].copy(),
        shapedirs=model.shapedirs * m[None, :, None],
        posedirs=model.posedirs * m[None, :, None] * feature_sign[None, None, :],
        hands_mean=model.hands_mean * aa_sign,
        hands_components=model.hands_components * aa_sign[None, :],
        side="left" if model.side == "right" else "right",
    )


def with_size_direction(model: HandModel, scale: float = 0.05) -> HandModel:
    """`model` whose first shape direction grows the hand about its centroid, as MANO's beta 0 roughly does."""
    shapedirs = model.shapedirs.copy()
    shapedirs[:, :, 0] = scale * (model.v_template - model.v_template.mean(0))
    return model.replace(shapedirs=shapedirs)


def add_vertices(model: HandModel, points: np.ndarray, weights: np.ndarray) -> HandModel:
    """`model` with extra unconnected vertices (n, 3) and their skin weights (n, 16); zero correctives/shape."""
    n = len(points)
    regressor = sp.hstack([model.J_regressor, sp.csr_matrix((model.J_regressor.shape[0], n))]).tocsr()
    return model.replace(
        v_template=np.concatenate([model.v_template, points]),
        weights=np.concatenate([model.weights, weights]),
        posedirs=np.concatenate([model.posedirs, np.zeros((n,) + model.posedirs.shape[1:])]),
        shapedirs=np.concatenate([model.shapedirs, np.zeros((n,) + model.shapedirs.shape[1:])]),
        J_regressor=regressor,
    )


def mano_dict(model: HandModel, *, left_bug: bool = False, shapedirs_as: str = "ch", ch_fields=(),
              seed: int = 0) -> dict:
    """The dict an official MANO pickle holds, from `model` (written as is; see `write_mano_pkl` for sides).

    shapedirs_as: 'ch' (Ch(x=...)), 'select' (Select over a wider Ch, as `Ch[:, :, :S]` pickles) or 'array'.
    ch_fields: other fields to wrap in a Ch, as some file versions do.
    left_bug: negate shapedirs[:, 0, :] as the official MANO_LEFT.pkl has it.
    """
    rng = np.random.default_rng(seed)
    shapedirs = model.shapedirs.copy()
    if left_bug:
        shapedirs[:, 0, :] *= -1
    if shapedirs_as == "ch":
        shapedirs_value = Ch(shapedirs)
    elif shapedirs_as == "select":
        wide = np.concatenate([shapedirs, rng.standard_normal(shapedirs.shape)], axis=2)
        idxs = np.arange(wide.size).reshape(wide.shape)[:, :, : shapedirs.shape[2]]
        shapedirs_value = Select(Ch(wide), idxs.ravel(), idxs.shape)
    elif shapedirs_as == "array":
        shapedirs_value = shapedirs
    else:
        raise ValueError(shapedirs_as)
    kintree = np.stack([np.where(model.parents < 0, ROOT_PARENT, model.parents), np.arange(len(model.parents))])
    joints = model.J_regressor @ model.v_template
    d = {
        "v_template": model.v_template.copy(),
        "f": model.faces.astype(np.uint32),
        "weights": model.weights.copy(),
        "posedirs": model.posedirs.copy(),
        "shapedirs": shapedirs_value,
        "J_regressor": sp.csc_matrix(model.J_regressor),
        "kintree_table": kintree.astype(np.uint32),
        "hands_components": model.hands_components.copy(),
        "hands_mean": model.hands_mean.copy(),
        "hands_coeffs": rng.standard_normal((8, model.hands_components.shape[0])),
        "J": joints,
        "bs_style": "lbs",
        "bs_type": "lrotmin",
    }
    for key in ch_fields:
        d[key] = Ch(d[key])
    return d


def write_mano_pkl(path, model: HandModel | None = None, side: str = "right", left_bug: bool = True, *,
                   shapedirs_as: str = "ch", ch_fields=(), protocol: int = 2, py2: bool = True,
                   override: dict | None = None, drop=()) -> Path:
    """Write `model` (default `tube_hand()`) as a MANO pickle of the given side; return the path.

    If `side` differs from model.side the model is mirrored (`mirror_x`) first, so the file holds a proper
    hand of that side. A left file gets MANO_LEFT's shapedirs x-sign bug when `left_bug`. `override` replaces
    (or adds) dict entries, `drop` removes them -- to build bad files.
    """
    model = tube_hand() if model is None else model
    if side != model.side:
        model = mirror_x(model)
    d = mano_dict(model, left_bug=(side == "left" and left_bug), shapedirs_as=shapedirs_as, ch_fields=ch_fields)
    d.update(override or {})
    for key in drop:
        d.pop(key)
    path = Path(path)
    path.write_bytes(dumps_like_mano(d, protocol=protocol, py2=py2))
    return path


# --------------------------------------------------------------------------------------------------------------------
# Malicious pickles: each one, loaded by plain pickle.loads, creates `marker`.


def _global(module: str, name: str) -> bytes:
    return pickle.GLOBAL + f"{module}\n{name}\n".encode()


def _text(s: str) -> bytes:
    data = s.encode()
    return pickle.BINUNICODE + struct.pack("<I", len(data)) + data


def _call(func: bytes, *args: bytes) -> bytes:
    return func + pickle.MARK + b"".join(args) + pickle.TUPLE + pickle.REDUCE


def _payload(kind: str, marker: Path) -> bytes:
    m = str(marker)
    touch = f"open({m!r}, 'w').close()"
    if kind == "os.system":
        return _call(_global("os", "system"), _text(f"touch '{m}'"))
    if kind == "posix.system":
        return _call(_global("posix", "system"), _text(f"touch '{m}'"))
    if kind in ("builtins.eval", "builtins.exec", "__builtin__.eval"):
        module, name = kind.split(".")
        return _call(_global(module, name), _text(touch))
    if kind == "subprocess.Popen":
        return _call(_global("subprocess", "Popen"),
                     pickle.MARK + _text("touch") + _text(m) + pickle.LIST)
    raise ValueError(kind)


MALICIOUS_KINDS = ("os.system", "posix.system", "builtins.eval", "builtins.exec", "__builtin__.eval",
                   "subprocess.Popen")


def malicious_pickle(kind: str, marker: Path) -> bytes:
    """A protocol 2 pickle whose top-level object is a call creating `marker` (kind: one of MALICIOUS_KINDS)."""
    return pickle.PROTO + b"\x02" + _payload(kind, marker) + pickle.STOP


class _Evil:
    """Pickles as posix.system('touch marker') wherever it sits in a structure."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        import os

        return os.system, (f"touch '{self.marker}'",)


def write_nested_malicious(path, marker: Path, key: str = "bs_style", **kwargs) -> Path:
    """A complete MANO pickle except that dict entry `key` is a call creating `marker` (a REDUCE inside the dict)."""
    return write_mano_pkl(path, override={key: _Evil(marker)}, **kwargs)


# --------------------------------------------------------------------------------------------------------------------
# A realistic MANO-format model: the open hand remeshed to MANO's budget and re-rigged.

MANO_VERTICES, MANO_LOOP = 778, 16


@functools.lru_cache(maxsize=4)
def mano_like_model(thicken_mm: float = 0.0) -> HandModel:
    """The open CC0 hand as MANO's file would hold it: 778 vertices, 1538 faces, one 16-vertex wrist loop,
    fingertips at MANO's tip vertex ids (layout.MANO_TIP_IDS), vertex 777 the wrist-loop vertex most bound to the
    wrist (DART copies its weights to the new wrist rings), no UVs, no face labels.

    The mesh is the open hand's with 4 wrist-loop vertices merged into their neighbours and then MeshLab's quadric
    edge collapse down to 778 vertices (boundary kept, no optimal placement, so every vertex is a source vertex and
    its skin weights, correctives and ten shape directions carry over exactly); the joint regressor is fitted anew
    to the source joints (template.regressor); the PCA pose basis and mean of 2000 anatomical samples.
    thicken_mm: push every vertex out along its normal first (a hand thicker than the one the gestures were
    authored on). Cached: about half a second.
    """
    from darthand.model.anatomy import sample_poses
    from darthand.model.layout import MANO_TIP_IDS
    from darthand.model.load import open_hand
    from darthand.model.topology import boundary_loops, vertex_normals
    from darthand.template.regressor import fit_regressor

    source = open_hand("right")
    vertices, faces = source.v_template, _merge_loop_vertices(source.faces, MANO_LOOP)
    if thicken_mm:
        vertices = vertices + thicken_mm * 1e-3 * vertex_normals(vertices, source.faces)
    keep, faces = _decimate(vertices, faces, MANO_VERTICES)
    tips = np.array([np.argmin(np.linalg.norm(vertices[keep] - vertices[t], axis=1)) for t in source.tip_ids])
    loop = boundary_loops(faces)[0]
    anchor = int(loop[np.argmax(source.weights[keep][loop, 0])])
    order = _mano_order(len(keep), dict(zip(tips.tolist(), MANO_TIP_IDS.tolist())) | {anchor: MANO_VERTICES - 1})
    keep = keep[order]
    faces = np.argsort(order)[faces]
    v, weights = vertices[keep], source.weights[keep]
    joints = np.asarray(source.J_regressor @ source.v_template)
    regressor, _ = fit_regressor(v, weights, joints, v[MANO_TIP_IDS])
    model = HandModel.create(v_template=v, faces=faces, weights=weights, posedirs=source.posedirs[keep],
                             J_regressor=regressor, parents=source.parents, shapedirs=source.shapedirs[keep],
                             tip_ids=MANO_TIP_IDS, side="right", meta={"source": "mano-like fixture"})
    poses = sample_poses(model, 2000, np.random.default_rng(7))[:, 3:]
    mean = poses.mean(0)
    components = np.linalg.svd(poses - mean, full_matrices=False)[2]
    return model.replace(hands_mean=mean, hands_components=components)


def write_mano_like(out_dir, thicken_mm: float = 0.0) -> tuple[Path, Path]:
    """Write `mano_like_model(thicken_mm)` as out_dir/MANO_RIGHT.pkl and MANO_LEFT.pkl (with MANO_LEFT's shapedirs
    x-sign bug); return both paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    model = mano_like_model(thicken_mm)
    return (write_mano_pkl(out / "MANO_RIGHT.pkl", model, side="right"),
            write_mano_pkl(out / "MANO_LEFT.pkl", model, side="left"))


def _merge_loop_vertices(faces: np.ndarray, size: int) -> np.ndarray:
    """Faces with the wrist loop cut down to `size` vertices: evenly spaced loop vertices merge into their next
    loop neighbour (each merge removes one vertex and one face)."""
    from darthand.model.topology import boundary_loops

    loop = boundary_loops(faces)[0]
    faces = faces.copy()
    drop = len(loop) - size
    for k in np.round(np.arange(drop) * len(loop) / max(drop, 1)).astype(int)[:drop]:
        faces[faces == loop[k]] = loop[(k + 1) % len(loop)]
    return faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])]


def _decimate(vertices: np.ndarray, faces: np.ndarray, target_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """(source vertex of each kept vertex (V',), faces over the kept vertices (F', 3)) after MeshLab's quadric
    edge collapse to `target_vertices`, keeping the boundary and vertex positions."""
    import pymeshlab

    from darthand.model.topology import boundary_loops
    from darthand.template.decimate import source_vertices

    loop = sum(len(lp) for lp in boundary_loops(faces))
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces))
    ms.meshing_remove_unreferenced_vertices()
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=2 * target_vertices - 2 - loop, qualitythr=0.5,
                                                preserveboundary=True, boundaryweight=10.0, optimalplacement=False,
                                                preservenormal=True, preservetopology=True, planarquadric=True)
    ms.meshing_remove_unreferenced_vertices()
    out = ms.current_mesh()
    keep = source_vertices(vertices, out.vertex_matrix(), tolerance=0.0)
    assert len(keep) == target_vertices, len(keep)
    return keep, out.face_matrix().astype(np.int64)


def _mano_order(n: int, fixed: dict) -> np.ndarray:
    """(n,) a vertex order in which vertex k of `fixed` lands at index fixed[k], the others in their order."""
    order = np.full(n, -1)
    order[list(fixed.values())] = list(fixed)
    order[order < 0] = [k for k in range(n) if k not in fixed]
    return order


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description="write a MANO-format fixture (MANO_RIGHT.pkl, MANO_LEFT.pkl)")
    parser.add_argument("out_dir")
    parser.add_argument("--thicken", type=float, default=0.0, metavar="MM", help="push the skin out by MM")
    args = parser.parse_args()
    for path in write_mano_like(args.out_dir, args.thicken):
        print(path)

