"""Texture files in a package: images linked or downsized into place (USD, glTF .gltf) or embedded (.glb).

UV convention: the model's UVs (`HandModel.uvs`) are OpenGL / OBJ / USD `st` style, v up: (0, 0) is the
bottom-left corner of the image and the texel in row r (row 0 at the top of the file), column c of a W x H image
has its centre at (u, v) = ((c + 0.5) / W, 1 - (r + 0.5) / H). The textures stage bakes with it
(model/atlas.py, textures/bake.py), USD writes it unchanged as `st`, glTF (origin top-left) stores (u, 1 - v)
(gltf_rig.gltf_texcoords).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from darthand.errors import InputError
from darthand.fileio import atomic_path
from darthand.model.hand_model import HandModel

def place_texture(src: str | os.PathLike, dst: str | os.PathLike, size: int | None = None,
                  srgb: bool = True) -> None:
    """Put the image `src` at `dst` in a package, atomically: a hard link (a copy across file systems) when it
    needs no resizing, else the image downsized by `texture_bytes`' rule."""
    src = _texture_file(src)
    image = _downsized(src, size, srgb)
    with atomic_path(dst) as tmp:
        if image is None:
            tmp.unlink()
            try:
                os.link(src, tmp)
            except OSError:
                shutil.copyfile(src, tmp)
        else:
            _write_image(image, tmp, src)


def texture_bytes(src: str | os.PathLike, size: int | None = None, srgb: bool = True) -> bytes:
    """The file bytes of image `src`, downsized so that its longer side is at most `size` pixels (never upsized,
    aspect kept, the source's pixel format kept). Colour images (`srgb`) are resized in linear light (sRGB ->
    linear -> resize -> sRGB), since averaging sRGB values darkens edges; data maps as stored."""
    src = _texture_file(src)
    image = _downsized(src, size, srgb)
    if image is None:
        return src.read_bytes()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / f"resized{src.suffix}"
        _write_image(image, out, src)
        return out.read_bytes()


def _texture_file(src: str | os.PathLike) -> Path:
    src = Path(src)
    if not src.is_file():
        raise InputError(f"{src}: texture file not found")
    return src


def _downsized(src: Path, size: int | None, srgb: bool):
    """An OpenImageIO buffer of `src` downsized to `size` (longer side), or None when it is small enough."""
    if size is None:
        return None
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(str(src))
    spec = buf.spec()
    if buf.has_error or spec.width == 0:
        raise InputError(f"{src}: cannot read image ({buf.geterror()})")
    if max(spec.width, spec.height) <= size:
        return None
    scale = size / max(spec.width, spec.height)
    w, h = max(1, round(spec.width * scale)), max(1, round(spec.height * scale))
    if srgb:
        buf = oiio.ImageBufAlgo.colorconvert(buf, "sRGB", "linear")
    buf = oiio.ImageBufAlgo.resize(buf, roi=oiio.ROI(0, w, 0, h, 0, 1, 0, spec.nchannels))
    if srgb:
        buf = oiio.ImageBufAlgo.colorconvert(buf, "linear", "sRGB")
    buf.set_write_format(spec.format)
    return buf


def _write_image(buf, path: Path, src: Path) -> None:
    if not buf.write(str(path)):
        raise InputError(f"{src}: could not write the resized image ({buf.geterror()})")




def check_textures_fit(model: HandModel, textures: list | tuple) -> None:
    """InputError when skin textures are asked for a model without UVs (they could not be mapped)."""
    if textures and not model.has_uvs:
        raise InputError(f"{model.meta.get('source', 'model')}: the model has no UVs, so the skin textures cannot "
                         "be mapped (darthand.model.atlas.ensure_uvs makes the atlas they were baked for)")


