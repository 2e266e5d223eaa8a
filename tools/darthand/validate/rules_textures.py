"""Texture rules: where the files are, whether they can be read, their size and how they are read.

    tex.absolute-path       the authored path / URI is absolute (or a file:// or http:// URI): the package breaks
                            when moved
    tex.path-escapes        the path, resolved against the layer (USD) or the .gltf (glTF) that names it, leaves
                            the package folder
    tex.symlink-outside     the file is inside the package but is a symlink to somewhere outside it
    tex.missing             nothing at the path (or not in the usdz)
    tex.unreadable          OpenImageIO cannot open it, or it is corrupt, or it is not a regular file (a FIFO or
                            device is never opened). By default a PNG's signature, header
                            chunk CRC and final IEND chunk are checked (catches truncated and foreign files at the
                            cost of reading 45 bytes); `deep` walks every chunk's CRC and decodes every image
    tex.not-power-of-two    width or height is not a power of two
    tex.albedo-colorspace   a colour input (diffuseColor, emissiveColor, specularColor) reads its texture `raw`
    tex.data-colorspace     a data input (roughness, metallic, normal, occlusion, opacity, ...) does not read its
                            texture `raw` (`auto` reads an 8-bit PNG as sRGB). glTF fixes colour spaces by slot,
                            so these two apply to USD only
    tex.unknown-id          texture variant ids the package records are in the texture catalogue (catalogs.py)
    file.array-too-large    an image with more than Limits.max_image_pixels pixels is not opened
"""

from __future__ import annotations

import os
import stat
import struct
import tempfile
import zlib
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from darthand.fileio import file_kind
from darthand.validate.asset import Limits, Package, TextureRef
from darthand.validate.catalogs import known_texture_ids
from darthand.validate.findings import Finding, finding

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PNG_IEND = b"\x00\x00\x00\x00IEND\xaeB`\x82"
URI_SCHEMES = ("file:", "http:", "https:", "ftp:")


@dataclass(frozen=True)
class ImageInfo:
    width: int
    height: int


def check_textures(pkg: Package, limits: Limits = Limits(), deep: bool = False) -> list[Finding]:
    out: list[Finding] = []
    seen: dict[object, list[Finding]] = {}
    real_root = Path(os.path.realpath(pkg.root))
    for ref in pkg.textures:
        path_findings = check_location(ref, pkg.root, real_root)
        out += path_findings
        if not path_findings:
            key = ref.member or (ref.file if ref.data is None else ref.path)
            if key not in seen:
                seen[key] = check_image(ref, pkg.root, limits, deep)
                out += seen[key]
        out += check_color_space(ref)
    return out + check_ids(pkg)


# ------------------------------------------------------------------------------------------------ locations


def check_location(ref: TextureRef, root: Path, real_root: Path | None = None) -> list[Finding]:
    """Path rules for a texture stored as a file (embedded images have no location to check). real_root: the
    package folder with symlinks resolved (computed when not given)."""
    if ref.data is not None:
        return []
    asset = ref.asset
    if not asset:
        return [finding("tex.missing", ref.path, "the texture's file path is empty")]
    if asset.lower().startswith(URI_SCHEMES) or os.path.isabs(asset) or (len(asset) > 1 and asset[1] == ":"):
        return [finding("tex.absolute-path", ref.path, f"texture path {asset!r} is absolute; package paths must be "
                        "relative")]
    if ref.member is not None:          # inside a usdz: escaping means leaving the archive's root
        if ref.member.startswith("../") or ref.member == "..":
            return [finding("tex.path-escapes", ref.path, f"texture path {asset!r} leads outside the usdz")]
        return [] if ref.file is not None else [finding("tex.missing", ref.path, f"{asset!r} is not in the usdz")]
    if ref.file is None:
        return [finding("tex.missing", ref.path, f"texture {asset!r} cannot be resolved")]
    lexical = Path(os.path.normpath(ref.file))
    if not _inside(lexical, Path(os.path.normpath(root))):
        return [finding("tex.path-escapes", ref.path, f"texture path {asset!r} leads outside the package folder "
                        f"(to {lexical})")]
    if not os.path.lexists(lexical):
        return [finding("tex.missing", ref.path, f"texture {asset!r} does not exist ({_rel(lexical, root)})")]
    real = Path(os.path.realpath(lexical))
    if not _inside(real, real_root or Path(os.path.realpath(root))):
        return [finding("tex.symlink-outside", ref.path, f"texture {_rel(lexical, root)} is a link to {real}, "
                        "outside the package folder")]
    if not real.exists():
        return [finding("tex.missing", ref.path, f"texture {_rel(lexical, root)} is a broken link")]
    mode = real.stat().st_mode
    if not stat.S_ISREG(mode):          # a FIFO would block the decoder forever, a device never end
        return [finding("tex.unreadable", ref.path, f"texture {_rel(lexical, root)} is {file_kind(mode)}, not a "
                        "regular file; not opened")]
    return []


def _inside(path: Path, root: Path) -> bool:
    return path == root or root in path.parents


def _rel(path: Path, root: Path) -> str:
    try:
        return path.relative_to(root).as_posix()
    except ValueError:
        return str(path)


# ------------------------------------------------------------------------------------------------ images


def check_image(ref: TextureRef, root: Path, limits: Limits, deep: bool) -> list[Finding]:
    """tex.unreadable, file.array-too-large and tex.not-power-of-two for one image."""
    where = ref.path if ref.data is not None or ref.file is None else _rel(ref.file, root)
    try:
        info = image_info(ref)
        if info.width * info.height > limits.max_image_pixels:
            return [finding("file.array-too-large", where, f"texture is {info.width} x {info.height} pixels, above "
                            f"the limit of {limits.max_image_pixels} pixels")]
        if deep:
            verify_image(ref)
    except (OSError, ValueError) as e:
        return [finding("tex.unreadable", where, f"texture cannot be read: {e}")]
    if not (_pow2(info.width) and _pow2(info.height)):
        return [finding("tex.not-power-of-two", where, f"texture is {info.width} x {info.height}; engines need "
                        "power-of-two sizes for mipmapping and compression")]
    return []


def _pow2(n: int) -> bool:
    return n > 0 and n & (n - 1) == 0


def image_info(ref: TextureRef) -> ImageInfo:
    """Width and height from the image's header; ValueError / OSError when it is unreadable or (for PNG) its
    header chunk is corrupt or it does not end with IEND."""
    if ref.data is not None:
        if ref.data[:8] == PNG_SIGNATURE:
            return png_info(ref.data[:33], ref.data[-12:])
        with _as_file(ref.data) as path:
            return oiio_info(path)
    assert ref.file is not None, "a texture is embedded or in a file"
    path = Path(ref.file)
    with open(path, "rb") as f:
        head = f.read(33)
        if head[:8] == PNG_SIGNATURE:
            f.seek(max(0, os.fstat(f.fileno()).st_size - 12))
            png_info(head, f.read(12))
    return oiio_info(path)


def verify_image(ref: TextureRef) -> None:
    """The deep check: every PNG chunk's CRC, then a full decode by OpenImageIO."""
    if ref.data is not None:
        data = ref.data
    else:
        assert ref.file is not None, "a texture is embedded or in a file"
        data = Path(ref.file).read_bytes()
    if data[:8] == PNG_SIGNATURE:
        check_png_chunks(data)
    if ref.file is not None and ref.data is None:
        oiio_info(Path(ref.file), decode=True)
    else:
        with _as_file(data) as path:
            oiio_info(path, decode=True)


def png_info(head: bytes, tail: bytes) -> ImageInfo:
    """Size from a PNG's first 33 bytes (signature + IHDR, CRC checked); its last 12 must be the IEND chunk."""
    if len(head) < 33 or head[:8] != PNG_SIGNATURE:
        raise ValueError("not a PNG (bad signature)")
    length, kind = struct.unpack(">I4s", head[8:16])
    if kind != b"IHDR" or length != 13:
        raise ValueError("PNG does not start with a header chunk")
    if zlib.crc32(head[12:29]) != struct.unpack(">I", head[29:33])[0]:
        raise ValueError("PNG header chunk fails its CRC")
    if tail != PNG_IEND:
        raise ValueError("PNG does not end with an IEND chunk (truncated?)")
    width, height = struct.unpack(">II", head[16:24])
    return ImageInfo(width, height)


def check_png_chunks(data: bytes) -> None:
    """Walk every chunk: lengths inside the file, CRCs right, IEND last (ValueError naming the first bad chunk)."""
    pos, view = 8, memoryview(data)
    while pos + 12 <= len(data):
        length, kind = struct.unpack(">I4s", view[pos:pos + 8])
        end = pos + 12 + length
        if end > len(data):
            raise ValueError(f"PNG chunk {kind!r} at byte {pos} runs past the end of the file")
        if zlib.crc32(view[pos + 4:pos + 8 + length]) != struct.unpack(">I", view[pos + 8 + length:end])[0]:
            raise ValueError(f"PNG chunk {kind!r} at byte {pos} fails its CRC")
        pos = end
        if kind == b"IEND":
            return
    raise ValueError("PNG has no IEND chunk")


def oiio_info(path: Path, decode: bool = False) -> ImageInfo:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ValueError(f"OpenImageIO cannot open it ({_oiio_error(oiio)})")
    try:
        spec = inp.spec()
        info = ImageInfo(int(spec.width), int(spec.height))
        if decode and inp.read_image() is None:
            raise ValueError(f"OpenImageIO cannot decode it ({inp.geterror() or 'read failed'})")
    finally:
        inp.close()
    return info


@contextmanager
def _as_file(data: bytes):
    """An embedded image as a temporary file (OpenImageIO's Python binding reads files)."""
    with tempfile.TemporaryDirectory(prefix="darthand-validate-") as tmp:
        path = Path(tmp) / "image"
        path.write_bytes(data)
        yield path


def _oiio_error(oiio) -> str:
    try:
        return oiio.geterror() or "unknown format"
    except Exception:       # older bindings
        return "unknown format"


# ------------------------------------------------------------------------------------------------ colour spaces


def check_color_space(ref: TextureRef) -> list[Finding]:
    if ref.color_space is None:
        return []
    cs = ref.color_space or "auto"
    if ref.role == "color" and cs == "raw":
        return [finding("tex.albedo-colorspace", ref.path, "colour texture is read as raw; albedo is sRGB "
                        "(sourceColorSpace = \"sRGB\")")]
    if ref.role == "data" and cs != "raw":
        return [finding("tex.data-colorspace", ref.path, f"data map is read as {cs!r}; data maps must be read raw "
                        "(sourceColorSpace = \"raw\")")]
    return []


def check_ids(pkg: Package) -> list[Finding]:
    if not pkg.texture_ids:
        return []
    known, source = known_texture_ids(pkg.root)
    return [finding("tex.unknown-id", where, f"texture id {tid!r} is not in {source}")
            for tid, where in pkg.texture_ids if tid not in known]
