"""A `.usdz` of one variant combination of an asset package (e.g. for AR viewers and quick hand-offs).

The interface layer is opened with the chosen `texture` and `accessory` variants (payloads loaded) and flattened
into one layer: the rig, the chosen material and accessory, no variant sets. Flattening anchors asset paths to
absolute ones; they are rewritten to package-relative paths, the files they name are linked into a staging folder
with the same layout, and UsdUtils packages that folder (root layer first, 64-byte aligned, uncompressed, as
usdz requires).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from pxr import Sdf, Usd, UsdUtils

from darthand.errors import InputError
from darthand.export.package_files import ASSET_INFO, check_usd_package, read_asset_info
from darthand.export.usd_validate import select_variants
from darthand.fileio import atomic_path, staging_folder


def export_usdz(package: str | os.PathLike, out: str | os.PathLike, texture: str | None = None,
                accessory: str | None = None) -> list[str]:
    """Write `out` (.usdz) from the package folder (or its interface layer) `package` with the given variants
    (None: the asset's default selection). Returns the files inside the usdz, root layer first."""
    interface = interface_layer(package)
    root_dir = interface.parent
    out = Path(out)
    if out.suffix != ".usdz":
        raise InputError(f"{out}: the output must end in .usdz")
    check_usd_package(interface, root_dir)
    stage = Usd.Stage.Open(str(interface), Usd.Stage.LoadAll)
    select_variants(stage, {k: v for k, v in (("texture", texture), ("accessory", accessory)) if v is not None})
    flat = stage.Flatten()
    staging = staging_folder(out)
    try:
        root_name = f"{interface.stem}.usdc"

        def relocate(asset: str) -> str:
            if not asset:
                return asset
            src = Path(asset)
            if src.resolve() == interface.resolve():
                return f"./{root_name}"
            try:
                rel = src.resolve().relative_to(root_dir.resolve())
            except ValueError:
                raise InputError(f"{interface}: asset path {asset} is outside the package folder") from None
            dst = staging / rel
            dst.parent.mkdir(parents=True, exist_ok=True)
            if not dst.exists():
                try:
                    os.link(src, dst)
                except OSError:
                    shutil.copy2(src, dst)
            return f"./{rel.as_posix()}"

        UsdUtils.ModifyAssetPaths(flat, relocate)
        flat.Export(str(staging / root_name))
        out.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(out) as tmp:
            if not UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(staging / root_name)), str(tmp)):
                raise InputError(f"{out}: UsdUtils could not create the usdz package")
        return usdz_contents(out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def interface_layer(package: str | os.PathLike) -> Path:
    """The interface layer of a package folder (named in its asset.json, else the one .usda at its top), or the
    layer itself when given a file."""
    path = Path(package)
    if path.is_file():
        return path
    if not path.is_dir():
        raise InputError(f"{path}: no such USD package folder or layer")
    info = read_asset_info(path)
    if info:
        if "interface" not in info:
            raise InputError(f"{path / ASSET_INFO}: not a darthand asset.json (no 'interface')")
        return path / info["interface"]
    candidates = sorted(path.glob("*.usda"))
    if len(candidates) != 1:
        raise InputError(f"{path}: expected one interface .usda at the top of the package, found {len(candidates)}")
    return candidates[0]


def usdz_contents(path: str | os.PathLike) -> list[str]:
    """File names inside a usdz, in archive order (the first is the root layer)."""
    import zipfile
    with zipfile.ZipFile(path) as z:
        return [i.filename for i in z.infolist()]
