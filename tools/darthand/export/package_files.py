"""Every file a USD package refers to, resolved and checked before OpenUSD composes it or an image decoder reads it.

OpenUSD opens a stage's sublayers, references and payloads as it composes the stage, wherever they point: a
package from elsewhere could make it read any file of the machine, or block forever on a FIFO. So the package's
layers are walked one at a time first -- each one read alone by Sdf (which follows nothing) and only once it is
known to be a regular file inside the package -- and every asset path they author is resolved against its layer:

    layer      a sublayer, reference or payload (a file of a USD format): it must be a regular file inside the
               package (symlinks resolved), else the package must not be composed
    asset      any other asset path (textures, mostly): outside the package, or not a regular file, it must never
               be handed to an image decoder; composing the stage does not open it

A usdz is its own root: its layers and assets must be members of the archive.
"""

from __future__ import annotations

import os
import posixpath
import re
import stat
import zipfile
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

from darthand.errors import InputError
from darthand.fileio import file_kind, read_json

MAX_LAYERS = 100_000
_URI = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]+:")


@dataclass(frozen=True)
class Problem:
    """One asset path that must not be opened. role: 'layer' or 'asset'; where: the layer naming it (relative to
    the package); asset: the path as authored; target: what it resolves to."""

    role: str
    where: str
    asset: str
    target: str
    reason: str

    def __str__(self) -> str:
        return f"{self.where}: {self.role} @{self.asset}@ {self.reason}"


ASSET_INFO = "asset.json"


def read_asset_info(folder: str | os.PathLike) -> dict:
    """A package folder's asset.json ({} when there is none), after checking the fields readers use: interface (a
    .usd* file name at the package's top), side, options and model (objects), model.tip_ids (5 vertex indices),
    gestures.names (strings). InputError naming the file and field otherwise; nothing else in it is trusted."""
    path = Path(folder) / ASSET_INFO
    if not os.path.lexists(path):
        return {}
    info = read_json(path, "darthand asset.json", max_bytes=64 << 20)

    def fail(field: str, msg: str):
        raise InputError(f"{path}: field '{field}' {msg}")

    if not isinstance(info, dict):
        raise InputError(f"{path}: holds a {type(info).__name__}, expected a JSON object")
    interface = info.get("interface", "")
    if "interface" in info and not (isinstance(interface, str) and interface and "/" not in interface
                                    and "\\" not in interface and interface not in (".", "..")
                                    and is_layer_path(interface)):
        fail("interface", f"is {str(interface)[:60]!r}, expected the file name of a USD layer beside asset.json")
    if info.get("side") not in (None, "right", "left"):
        fail("side", f"is {str(info['side'])[:20]!r}, expected 'right' or 'left'")
    for key in ("options", "model", "gestures", "variants", "rig"):
        if key in info and not isinstance(info[key], dict):
            fail(key, f"is a {type(info[key]).__name__}, expected an object")
    tips = (info.get("model") or {}).get("tip_ids")
    if tips is not None and not (isinstance(tips, list) and len(tips) == 5
                                 and all(isinstance(t, int) and 0 <= t < 1 << 31 for t in tips)):
        fail("model.tip_ids", "must be 5 vertex indices")
    names = (info.get("gestures") or {}).get("names", [])
    if not (isinstance(names, list) and all(isinstance(n, str) for n in names)):
        fail("gestures.names", "must be a list of gesture names")
    return info


def is_layer_path(asset: str) -> bool:
    """True for a path of a USD file format (.usd, .usda, .usdc, .usdz, and any other Sdf knows)."""
    from pxr import Sdf

    ext = Path(asset.split("[", 1)[0]).suffix.lstrip(".")
    return bool(ext) and Sdf.FileFormat.FindByExtension(ext) is not None


def usd_problems(path: str | os.PathLike, root: str | os.PathLike | None = None) -> list[Problem]:
    """The problems of the USD package whose interface layer (or .usdz) is `path`, inside `root` (default: the
    layer's folder, or the .usdz itself). Walks every layer reachable from `path` without composing anything."""
    path = Path(os.path.abspath(path))
    if path.suffix.lower() == ".usdz":
        return _UsdzWalk(path).run()
    return _FolderWalk(path, Path(os.path.abspath(root or path.parent))).run()


def check_usd_package(path, root=None, what: str = "USD package") -> None:
    """InputError naming the first problem (and how many there are) when the package refers to anything that must
    not be opened: for commands that read the package's textures too (render, usdz)."""
    problems = usd_problems(path, root)
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise InputError(f"{path}: {what} not opened: {problems[0]}{more}")


def _references(layer_id: str) -> list[tuple[str, str]]:
    """(asset path, role) for every asset path one layer authors -- sublayers and payloads are layers; references
    and asset-valued attributes or metadata are layers when they name a USD file -- read by Sdf alone."""
    from pxr import Tf, UsdUtils

    try:
        sublayers, references, payloads = UsdUtils.ExtractExternalReferences(layer_id)
    except Tf.ErrorException:
        return []            # a layer that does not parse: the validators report it when they open it alone
    found = {a: "layer" for a in list(sublayers) + list(payloads)}
    for a in references:
        found.setdefault(a, "layer" if is_layer_path(a) else "asset")
    return list(found.items())


class _FolderWalk:
    """A package folder: files on disk under `root`."""

    def __init__(self, interface: Path, root: Path):
        self.interface, self.root = interface, root
        self.real_root = os.path.realpath(root)
        self.problems: list[Problem] = []

    def run(self) -> list[Problem]:
        reason = self.unsafe(self.interface)
        if reason:
            return [Problem("layer", self.label(self.interface), self.interface.name, str(self.interface), reason)]
        todo, seen = [self.interface], {self.interface}
        while todo:
            if len(seen) > MAX_LAYERS:
                self.problems.append(Problem("layer", self.label(todo[0]), "...", "", f"is one of more than "
                                             f"{MAX_LAYERS} layers"))
                break
            layer = todo.pop()
            for asset, role in _references(str(layer)):
                target = self.resolve(layer, asset)
                reason = self.unsafe(target) if target is not None else "is an expression or URI this check " \
                                                                        "cannot resolve"
                if reason and reason != "does not exist":      # a missing file is safe: the readers report it
                    self.problems.append(Problem(role, self.label(layer), asset, str(target), reason))
                elif role == "layer" and not reason and target is not None and target not in seen:
                    seen.add(target)
                    todo.append(target)
        return self.problems

    def resolve(self, layer: Path, asset: str) -> Path | None:
        """The file `asset` names from `layer` (a package-relative path names its archive); None for what cannot
        be resolved without a resolver plugin or expression evaluation (URIs, `${VAR}` expressions)."""
        if asset.startswith("`") or "${" in asset:
            return None
        if asset.lower().startswith("file://"):
            asset = unquote(asset[len("file://"):])
        elif _URI.match(asset):
            return None
        a = asset.split("[", 1)[0]
        return Path(os.path.normpath(a if os.path.isabs(a) else os.path.join(layer.parent, a)))

    def unsafe(self, target: Path) -> str:
        """Why `target` must not be opened ('' when it may)."""
        root = str(self.root)
        if not (str(target) == root or str(target).startswith(root + os.sep)):
            return f"leads outside the package ({target})"
        real = os.path.realpath(target)
        if not (real == self.real_root or real.startswith(self.real_root + os.sep)):
            return f"is a link to {real}, outside the package"
        try:
            st = os.stat(target)
        except OSError:
            return "does not exist"
        if not stat.S_ISREG(st.st_mode):
            return f"is {file_kind(st.st_mode)}, not a regular file"
        return ""

    def label(self, path: Path) -> str:
        try:
            return path.relative_to(self.root).as_posix()
        except ValueError:
            return str(path)


class _UsdzWalk:
    """A .usdz: layers and assets are members of the archive; anything else is outside."""

    def __init__(self, archive: Path):
        self.archive = archive
        self.problems: list[Problem] = []

    def run(self) -> list[Problem]:
        try:
            st = os.stat(self.archive)
        except OSError:
            return [Problem("layer", self.archive.name, self.archive.name, str(self.archive), "does not exist")]
        if not stat.S_ISREG(st.st_mode):
            return [Problem("layer", self.archive.name, self.archive.name, str(self.archive),
                            f"is {file_kind(st.st_mode)}, not a regular file")]
        try:
            with zipfile.ZipFile(self.archive) as z:
                members = [i.filename for i in z.infolist()]
        except (zipfile.BadZipFile, OSError):
            return []                        # not a usdz: the reader reports it
        layers = [m for m in members if is_layer_path(m)]
        todo, seen = layers[:1], set(layers[:1])
        while todo:
            member = todo.pop()
            from pxr import Ar

            for asset, role in _references(Ar.JoinPackageRelativePath(str(self.archive), member)):
                inner = self.member(member, asset)
                if inner is None:
                    self.problems.append(Problem(role, member, asset, asset, "leads outside the usdz"))
                elif inner in members and role == "layer" and inner not in seen:
                    seen.add(inner)
                    todo.append(inner)
        return self.problems

    @staticmethod
    def member(layer: str, asset: str) -> str | None:
        """The archive member `asset` names from the member `layer` (None when it leaves the archive)."""
        if _URI.match(asset) or os.path.isabs(asset) or asset.startswith("`") or "${" in asset:
            return None
        inner = asset.split("[", 1)[1].rstrip("]") if "[" in asset else asset
        path = posixpath.normpath(posixpath.join(posixpath.dirname(layer), inner))
        return None if path == ".." or path.startswith("../") else path
