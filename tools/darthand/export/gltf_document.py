"""A glTF 2.0 document under construction: pygltflib's object model plus the one binary buffer it points into.

`GltfDocument` appends typed arrays to the buffer (4-byte aligned, one bufferView each), creates the accessors that
describe them (with the min/max glTF requires for positions and animation times) and finally serialises the
document either as one `.glb` (JSON chunk + binary chunk, images embedded) or as a `.gltf` JSON file with a `.bin`
buffer and images beside it, referenced by relative URIs.

pygltflib does the JSON object model and the GLB container; it has no notion of numpy arrays or alignment, which is
the little this module adds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib as gl

from darthand.fileio import write_bytes

# glTF accessor component types for the numpy dtypes the writers use.
COMPONENT = {np.dtype(np.float32): gl.FLOAT, np.dtype(np.uint8): gl.UNSIGNED_BYTE,
             np.dtype(np.uint16): gl.UNSIGNED_SHORT, np.dtype(np.uint32): gl.UNSIGNED_INT}
# Accessor type from the number of components per element.
ELEMENT = {1: gl.SCALAR, 2: gl.VEC2, 3: gl.VEC3, 4: gl.VEC4, 16: gl.MAT4}
GENERATOR = "darthand glTF exporter"


class GltfDocument:
    """pygltflib `GLTF2` being filled, with the binary buffer kept as a growing bytearray (buffer 0)."""

    def __init__(self, generator: str = GENERATOR):
        self.gltf = gl.GLTF2(asset=gl.Asset(version="2.0", generator=generator), scene=0, scenes=[gl.Scene(nodes=[])])
        self.blob = bytearray()

    # ------------------------------------------------------------------------------------------- binary data

    def buffer_view(self, data: bytes, target: int | None = None) -> int:
        """Append `data` (padded to a 4-byte boundary first) as a new bufferView; returns its index."""
        self.blob += b"\0" * (-len(self.blob) % 4)
        view = gl.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=len(data), target=target)
        self.blob += data
        self.gltf.bufferViews.append(view)
        return len(self.gltf.bufferViews) - 1

    def accessor(self, array: np.ndarray, *, target: int | None = gl.ARRAY_BUFFER, minmax: bool = False,
                 normalized: bool = False, matrix: bool = False, name: str | None = None) -> int:
        """Store `array` (N,) or (N, C) of float32/uint8/uint16/uint32 as an accessor; returns its index.

        matrix: the rows of `array` (N, 16) are column-major 4x4 matrices (type MAT4). minmax: record the
        per-component min and max (glTF requires them for POSITION and animation inputs).
        """
        a = np.ascontiguousarray(array)
        if a.dtype not in COMPONENT:
            raise TypeError(f"glTF accessor: unsupported dtype {a.dtype}")
        width = 1 if a.ndim == 1 else a.shape[1]
        kind = gl.MAT4 if matrix else ELEMENT[width]
        acc = gl.Accessor(bufferView=self.buffer_view(a.tobytes(), target), componentType=COMPONENT[a.dtype],
                          count=int(a.shape[0]), type=kind, normalized=True if normalized else None, name=name)
        if minmax:
            flat = a.reshape(a.shape[0], -1)
            acc.min = [_number(x) for x in flat.min(0)]
            acc.max = [_number(x) for x in flat.max(0)]
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1

    def sparse_accessor(self, array: np.ndarray, *, name: str | None = None) -> int:
        """float32 (N, C) data that is mostly zero rows as a sparse accessor (no bufferView: zeros, plus the
        non-zero rows by index), with min/max; a dense one when that is smaller. Returns its index."""
        a = np.ascontiguousarray(array, dtype=np.float32)
        rows = np.flatnonzero(np.any(a != 0, axis=1))
        index_type = np.uint16 if len(a) <= 65536 else np.uint32
        if len(rows) * (a[0].nbytes + np.dtype(index_type).itemsize) >= a.nbytes:
            return self.accessor(a, minmax=True, name=name)
        acc = gl.Accessor(componentType=gl.FLOAT, count=int(len(a)), type=ELEMENT[a.shape[1]], name=name,
                          byteOffset=None, min=[_number(x) for x in a.min(0)], max=[_number(x) for x in a.max(0)])
        if len(rows):
            acc.sparse = gl.Sparse(
                count=int(len(rows)),
                indices=gl.AccessorSparseIndices(bufferView=self.buffer_view(rows.astype(index_type).tobytes()),
                                                 componentType=COMPONENT[np.dtype(index_type)]),
                values=gl.AccessorSparseValues(bufferView=self.buffer_view(a[rows].tobytes())))
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1

    def indices(self, faces: np.ndarray) -> int:
        """Triangle indices (F, 3) as the smallest unsigned type that holds them."""
        f = np.asarray(faces).reshape(-1)
        dtype = np.uint16 if f.max(initial=0) < 65535 else np.uint32  # 65535 is the primitive-restart value
        return self.accessor(f.astype(dtype), target=gl.ELEMENT_ARRAY_BUFFER)

    # ------------------------------------------------------------------------------------------- objects

    def add(self, kind: str, obj) -> int:
        """Append `obj` to the document's list `kind` ('nodes', 'meshes', ...); returns its index."""
        items = getattr(self.gltf, kind)
        items.append(obj)
        return len(items) - 1

    def image(self, name: str, *, png: bytes | None = None, uri: str | None = None) -> int:
        """A PNG image: embedded in the buffer (`png`) or referenced by a relative `uri`."""
        if png is not None:
            return self.add("images", gl.Image(name=name, mimeType="image/png",
                                               bufferView=self.buffer_view(png)))
        return self.add("images", gl.Image(name=name, uri=uri))

    def use_extension(self, name: str) -> None:
        if name not in self.gltf.extensionsUsed:
            self.gltf.extensionsUsed.append(name)

    # ------------------------------------------------------------------------------------------- output

    def glb_bytes(self) -> bytes:
        """The whole document as one GLB file (JSON chunk, then the binary chunk)."""
        self.gltf.buffers = [gl.Buffer(byteLength=len(self.blob))]
        self.gltf.set_binary_blob(bytes(self.blob))
        return b"".join(bytes(part) for part in self.gltf.save_to_bytes())

    def write(self, path: str | Path) -> list[Path]:
        """Write `path` (.glb, or .gltf with `<stem>.bin` beside it) atomically; returns the files written.

        Images given by URI are not written here (the caller places them next to the .gltf).
        """
        path = Path(path)
        if path.suffix.lower() == ".glb":
            write_bytes(path, self.glb_bytes())
            return [path]
        bin_path = path.with_suffix(".bin")
        self.gltf.buffers = [gl.Buffer(byteLength=len(self.blob), uri=bin_path.name)]
        write_bytes(bin_path, bytes(self.blob))
        write_bytes(path, self.gltf.gltf_to_json(separators=(",", ":"), indent=None).encode())
        return [path, bin_path]


def _number(x) -> float | int:
    """A JSON number that reads back as exactly the stored element (float32 -> the same double)."""
    return int(x) if np.issubdtype(type(x), np.integer) else float(x)
