"""Triangle meshes into embreex scenes by a buffer copy, not embreex's per-element one.

embreex's TriangleMesh fills Embree's vertex and index buffers one element at a time through Python indexing of
the numpy arrays (about 0.1 us per number: 1.9 ms for the 1,769-vertex hand, 5 ms for a 3,000-vertex ring, every
frame, since a new pose is a new scene). `add_triangles` makes the same geometry through Embree's own C API
(ctypes, the library embreex loads): rtcNewGeometry, rtcSetNewGeometryBuffer (the same formats and strides as
embreex: FLOAT3 vertices at a 16-byte stride, UINT3 indices), one numpy copy into each buffer, rtcCommitGeometry,
rtcAttachGeometry. Embree receives the same numbers, so the scene it builds, and every hit in it, is the same.

embreex does not expose a scene's RTCScene handle to Python; it is the first field of its EmbreeScene object.
`_Api.load` checks that layout before trusting it (the object's size, and a value written through the public
`is_committed` attribute read back at the next field's offset); when anything differs (another embreex), meshes
go through TriangleMesh as before. `device` is the process's one Embree device, for these scenes and scene.py's.
"""

from __future__ import annotations

import ctypes
import threading
from pathlib import Path

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh
from embreex.rtcore import EmbreeDevice

# Embree 4 (include/embree4/rtcore_common.h, rtcore_buffer.h, rtcore_geometry.h)
GEOMETRY_TYPE_TRIANGLE = 0
BUFFER_TYPE_INDEX, BUFFER_TYPE_VERTEX = 0, 1
FORMAT_UINT3, FORMAT_FLOAT3 = 0x5003, 0x9003
VERTEX_STRIDE, INDEX_STRIDE = 16, 12          # as embreex's Vertex (x, y, z, pad) and Triangle (v0, v1, v2)
_SCENE_OFFSET = 16                            # EmbreeScene: PyObject header, then RTCScene scene_i, int is_committed
_PROBE = 0x5AD17E13
_DEVICE = None


def device() -> EmbreeDevice:
    """One Embree device for the process (creating one per scene costs more than building the hand)."""
    global _DEVICE
    if _DEVICE is None:
        _DEVICE = EmbreeDevice()
    return _DEVICE


class _Api:
    """The Embree functions `add_triangles` calls, or None when embreex's layout is not the one checked for."""

    _loaded: "_Api | None | bool" = False
    _lock = threading.Lock()
    # set by __init__ from the library: rtcNewGeometry as NewGeometry, ...
    NewGeometry: ctypes._NamedFuncPointer
    SetNewGeometryBuffer: ctypes._NamedFuncPointer
    CommitGeometry: ctypes._NamedFuncPointer
    AttachGeometry: ctypes._NamedFuncPointer
    ReleaseGeometry: ctypes._NamedFuncPointer
    GetSceneDevice: ctypes._NamedFuncPointer
    ReleaseDevice: ctypes._NamedFuncPointer

    def __init__(self, lib: ctypes.CDLL):
        p, u, i, z = ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_size_t
        for name, res, args in (("rtcNewGeometry", p, (p, i)), ("rtcSetNewGeometryBuffer", p, (p, i, u, i, z, z)),
                                ("rtcCommitGeometry", None, (p,)), ("rtcAttachGeometry", u, (p, p)),
                                ("rtcReleaseGeometry", None, (p,)), ("rtcGetSceneDevice", p, (p,)),
                                ("rtcReleaseDevice", None, (p,))):
            f = getattr(lib, name)
            f.restype, f.argtypes = res, args
            setattr(self, name[3:], f)

    @classmethod
    def load(cls) -> "_Api | None":
        with cls._lock:
            if cls._loaded is False:
                cls._loaded = cls._open()
            return cls._loaded if isinstance(cls._loaded, _Api) else None

    @classmethod
    def _open(cls) -> "_Api | None":
        libs = sorted((Path(rtcore_scene.__file__).parent.parent / "embreex.libs").glob("libembree4*.so*"))
        if len(libs) != 1 or rtcore_scene.EmbreeScene.__basicsize__ != 40:
            return None
        try:
            api = cls(ctypes.CDLL(str(libs[0])))
        except (OSError, AttributeError):
            return None
        probe = rtcore_scene.EmbreeScene(device())
        probe.is_committed = _PROBE
        ok = ctypes.c_int.from_address(id(probe) + _SCENE_OFFSET + 8).value == _PROBE
        probe.is_committed = 0
        return api if ok and scene_handle(probe) else None


def scene_handle(scene: rtcore_scene.EmbreeScene) -> int:
    """The RTCScene handle inside an embreex scene (its first field)."""
    return ctypes.c_void_p.from_address(id(scene) + _SCENE_OFFSET).value or 0


def add_triangles(scene: rtcore_scene.EmbreeScene, vertices: np.ndarray, faces: np.ndarray) -> None:
    """Attach a triangle mesh (vertices (N, 3), faces (F, 3) int, 0 <= index < N) to an uncommitted embreex scene,
    as embreex's TriangleMesh(scene, vertices float32, faces int32) does (geomIDs in order of attachment)."""
    api = _Api.load()
    vertices = np.ascontiguousarray(vertices, np.float32)
    faces = np.ascontiguousarray(faces, np.int32)
    if api is None or not len(vertices) or not len(faces):
        TriangleMesh(scene, vertices, faces)
        return
    handle = scene_handle(scene)
    dev = api.GetSceneDevice(handle)
    try:
        geom = api.NewGeometry(dev, GEOMETRY_TYPE_TRIANGLE)
    finally:
        api.ReleaseDevice(dev)
    if not geom:
        raise RuntimeError("Embree could not make a triangle geometry")
    try:
        v = api.SetNewGeometryBuffer(geom, BUFFER_TYPE_VERTEX, 0, FORMAT_FLOAT3, VERTEX_STRIDE, len(vertices))
        f = api.SetNewGeometryBuffer(geom, BUFFER_TYPE_INDEX, 0, FORMAT_UINT3, INDEX_STRIDE, len(faces))
        if not v or not f:
            raise RuntimeError("Embree could not allocate a triangle mesh's buffers")
        vb = np.ctypeslib.as_array((ctypes.c_float * (4 * len(vertices))).from_address(v)).reshape(-1, 4)
        vb[:, :3] = vertices
        vb[:, 3] = 0
        np.ctypeslib.as_array((ctypes.c_uint32 * (3 * len(faces))).from_address(f)).reshape(-1, 3)[:] = faces
        api.CommitGeometry(geom)
        api.AttachGeometry(handle, geom)
    finally:
        api.ReleaseGeometry(geom)
