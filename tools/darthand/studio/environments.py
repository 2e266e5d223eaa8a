"""The environment maps the studio offers (render/environment.py's contract): the built-in set
(render/environment.list_builtin) and the maps of a folder (`darthand studio --environments DIR`), each with a
thumbnail and a copy the live view loads.

A map's id is what a studio scene names: a built-in map's name ("studio"), a folder map's file name ("sky.hdr"),
so the two never collide. The listing opens each file's header only (decodes, 2:1); a fault found when the
pixels are first decoded by render/environment.read_map (truncated data, NaN/Inf, negative values) marks the map
unusable from then on, with read_map's one-line reason. Made files are cached under BUILD/studio/cache, keyed by
the map's path, size and modification time:
- the thumbnail: THUMB_WIDTH x THUMB_HEIGHT sRGB PNG, box-filtered and tone-mapped (exposed to the map's own
  log-average luminance, then Reinhard's x / (1 + x)), for picking by eye;
- the live map: the map itself as an RGBE Radiance .hdr (three.js's HDRLoader reads it; EXR's many compressions
  are not all in three.js's EXRLoader), downsized to at most LIVE_WIDTH wide: linear radiance in the map's units.
"""

from __future__ import annotations

import hashlib
import os
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from darthand.errors import InputError
from darthand.fileio import atomic_path
from darthand.processes import native_stderr_captured
from darthand.render.environment import SUFFIXES, list_builtin, map_path, read_map
from darthand.render.image import first_line, write_png
from darthand.studio.request_error import RequestError
from darthand.textures.color import encode_srgb8

THUMB_WIDTH, THUMB_HEIGHT = 128, 64
LIVE_WIDTH = 1024
MAX_FOLDER_MAPS = 1000
KEY_VALUE = 0.3                  # the thumbnail's exposure: log-average luminance shown at this linear value


@dataclass
class EnvironmentMap:
    """One map: `id` (what scenes name), `source` ('builtin' or 'folder'), its file, and `reason` (None while
    usable, else the one-line fault)."""

    id: str
    source: str
    path: Path
    reason: str | None = None

    def to_json(self) -> dict:
        doc = {"id": self.id, "source": self.source, "usable": self.reason is None}
        return {**doc, "reason": self.reason} if self.reason else doc

    @property
    def cache_key(self) -> str:
        """A hex digest of the file's path, size and modification time (a changed file gets new cached copies)."""
        st = self.path.stat()
        return hashlib.sha256(f"{self.path}|{st.st_size}|{st.st_mtime_ns}".encode()).hexdigest()[:20]


class EnvironmentSet:
    """The built-in maps and those of `folder` (top level, .exr and .hdr), listed once when opened."""

    def __init__(self, folder=None):
        self.maps: dict[str, EnvironmentMap] = {}
        for name in list_builtin():
            self.maps[name] = EnvironmentMap(name, "builtin", map_path(name))
        self.folder = None if folder is None else Path(folder).resolve()
        if self.folder is not None:
            if not self.folder.is_dir():
                raise InputError(f"--environments {folder}: not a folder of environment maps (.exr, .hdr)")
            for path in _map_files(self.folder)[:MAX_FOLDER_MAPS]:
                self.maps[path.name] = EnvironmentMap(path.name, "folder", path)
        for env in self.maps.values():
            env.reason = header_fault(env.path)
        self._lock = threading.Lock()

    def listing(self) -> list[dict]:
        """[{id, source, usable, reason?}] in a stable order: built-ins first, then the folder's, by id."""
        return [m.to_json() for m in sorted(self.maps.values(), key=lambda m: (m.source != "builtin", m.id))]

    def get(self, map_id) -> EnvironmentMap:
        """The usable map of that id; RequestError 404 (unknown) or 422 (listed unusable, with its reason)."""
        env = self.maps.get(map_id) if isinstance(map_id, str) else None
        if env is None:
            raise RequestError(404, f"environment {map_id!r} is not one of the studio's environment maps")
        if env.reason is not None:
            raise RequestError(422, f"environment {map_id!r} is unusable: {env.reason}")
        return env

    def job_map(self, map_id) -> str:
        """What a lights document's environment.map holds for this id: a built-in's name, a folder map's path. The
        map is decoded first (read_map keeps the last few per process), so a fault is the studio's 422 and the map
        is listed unusable from then on."""
        env = self.get(map_id)
        with self._lock:
            self._decoded(env)
        return env.id if env.source == "builtin" else str(env.path)

    def thumbnail(self, map_id, cache: Path) -> bytes:
        """The map's thumbnail PNG bytes (made once)."""
        env = self.get(map_id)
        return self._cached(env, cache / f"environment_{env.cache_key}.png", write_thumbnail)

    def live_map(self, map_id, cache: Path) -> bytes:
        """The map as RGBE .hdr bytes for the live view (made once)."""
        env = self.get(map_id)
        return self._cached(env, cache / f"environment_{env.cache_key}.hdr", write_live_map)

    def _cached(self, env: EnvironmentMap, path: Path, make) -> bytes:
        with self._lock:
            if not path.is_file():
                make(self._decoded(env), path)
            return path.read_bytes()

    def _decoded(self, env: EnvironmentMap) -> np.ndarray:
        """(H, 2H, 3) float32 linear pixels of the map (render/environment.read_map); its InputError marks the map
        unusable with read_map's reason (the path left out) and is a RequestError 422."""
        try:
            return read_map(env.path)
        except InputError as e:
            env.reason = str(e).removeprefix(f"{env.path}: ")
            raise RequestError(422, f"environment {env.id!r} is unusable: {env.reason}") from None


def _map_files(folder: Path) -> list[Path]:
    try:
        names = sorted(os.listdir(folder))
    except OSError as e:
        raise InputError(f"{folder}: cannot list the environment maps ({e.strerror})") from None
    return [folder / n for n in names if n.lower().endswith(SUFFIXES) and not n.startswith(".")
            and (folder / n).is_file()]


def header_fault(path: Path) -> str | None:
    """Why the file's header rules it out as an equirectangular map (one line, worded as read_map's refusal without
    the path), or None."""
    with native_stderr_captured():
        inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return f"cannot read environment map: {first_line(oiio.geterror()) or 'unknown format'}"
    spec = inp.spec()
    inp.close()
    if spec.width != 2 * spec.height:
        return f"environment map is {spec.width}x{spec.height}, not 2:1 (equirectangular)"
    return None


# ------------------------------------------------------------------------------------------------ made files


def write_thumbnail(radiance: np.ndarray, path: Path) -> None:
    """Write the THUMB_WIDTH x THUMB_HEIGHT sRGB PNG of an (H, W, 3) linear map."""
    small = resized(radiance, THUMB_WIDTH)
    write_png(path, encode_srgb8(tone_mapped(small)))


def tone_mapped(radiance: np.ndarray) -> np.ndarray:
    """(H, W, 3) linear radiance exposed so its log-average luminance reads KEY_VALUE, then x / (1 + x): display
    values in [0, 1)."""
    luminance = radiance @ np.asarray([0.2126, 0.7152, 0.0722], np.float32)
    log_average = float(np.exp(np.mean(np.log(luminance + 1e-4))))
    x = radiance * np.float32(KEY_VALUE / max(log_average, 1e-6))
    return (x / (1 + x)).astype(np.float32)


def write_live_map(radiance: np.ndarray, path: Path) -> None:
    """Write the map (downsized to at most LIVE_WIDTH wide) as an RGBE Radiance .hdr."""
    small = resized(radiance, min(LIVE_WIDTH, radiance.shape[1]))
    with atomic_path(path) as tmp:
        buf = oiio.ImageBuf(np.ascontiguousarray(small, np.float32))
        if not buf.write(str(tmp)):
            raise InputError(f"{path}: cannot write the live environment map ({buf.geterror()})")


def resized(radiance: np.ndarray, width: int) -> np.ndarray:
    """(width / 2, width, 3) float32 of a 2:1 map, area-filtered (unchanged when already that size)."""
    if radiance.shape[1] == width:
        return radiance
    height = width // 2
    out = oiio.ImageBufAlgo.resize(oiio.ImageBuf(np.ascontiguousarray(radiance)), filtername="box",
                                   roi=oiio.ROI(0, width, 0, height, 0, 1, 0, 3))
    pixels = out.get_pixels(oiio.FLOAT)
    assert pixels is not None, out.geterror()
    return np.maximum(pixels.reshape(height, width, 3), 0).astype(np.float32)
