"""`validate_paths`: check USD and glTF hand packages and return one `Report`.

Per file: the format's reader and validators (rules_usd: OpenUSD's registry; rules_gltf: the Khronos validator),
then the shared rules on what was read (rules_mesh, rules_rig, rules_textures, rules_accessories) and, with
`render`, the reference renderer's checks. A file that cannot be read gives one `file.unreadable` finding (exit
code 2); any exception while reading or checking becomes a finding naming the file, never a traceback. Nothing is
written to the checked files: USD stages are opened with an anonymous session layer and never saved, glTF files
and images are only read.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from darthand.errors import DarthandError
from darthand.fileio import regular_file
from darthand.validate import gltf_reader
from darthand.validate.asset import Limits, Package
from darthand.validate.findings import SEVERITIES, UNREADABLE, Finding, PackageResult, Report, finding
from darthand.validate.rules_accessories import check_accessories
from darthand.validate.rules_gltf import check_gltf
from darthand.validate.rules_mesh import check_mesh
from darthand.validate.rules_render import render_findings, renderer
from darthand.validate.rules_rig import check_rig
from darthand.validate.rules_textures import check_textures

USD_SUFFIXES = (".usda", ".usdc", ".usd", ".usdz")
GLTF_SUFFIXES = (".gltf", ".glb")


def validate_paths(paths, render: bool = False, deep: bool = False, limits: Limits = Limits()) -> Report:
    """Validate every package named by `paths` (files, or package folders: a USD package's interface layer, or
    the .glb/.gltf files at a folder's top). render: also render each asset and apply the renderer's checks;
    deep: decode every texture fully instead of checking its header and end."""
    check = None
    if render:
        check = renderer()
    report = Report()
    for given in paths:
        try:
            files, problem = package_files(Path(given))
        except OSError as e:
            files, problem = [], e.strerror or str(e)
        if problem:
            report.packages.append(PackageResult(str(given), "unknown", [finding(UNREADABLE, str(given), problem)]))
        for path in files:
            report.packages.append(validate_file(path, check, deep, limits))
    return report


def package_files(path: Path) -> tuple[list[Path], str]:
    """The files to check for one argument, or a one-line reason why there are none."""
    if path.is_file():
        return [path], ""
    if not path.exists():
        return [], "no such file or folder"
    if not path.is_dir():
        return [], "not a regular file"
    if os.path.lexists(path / "asset.json") or any(path.glob("*.usda")):
        from darthand.export.usdz import interface_layer  # lazy: OpenUSD takes 0.6 s to import
        try:
            return [interface_layer(path)], ""
        except DarthandError as e:
            return [], str(e).split(": ", 1)[-1]
    files = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in USD_SUFFIXES + GLTF_SUFFIXES)
    return (files, "") if files else ([], "the folder holds no USD package and no .usd*/.glb/.gltf file")


def validate_file(path: Path, render_check=None, deep: bool = False, limits: Limits = Limits()) -> PackageResult:
    """Every rule on one file."""
    t0 = time.perf_counter()
    suffix = path.suffix.lower()
    fmt = {".usdz": "usdz", ".glb": "glb", ".gltf": "gltf"}.get(suffix, "usd" if suffix in USD_SUFFIXES else "unknown")
    result = PackageResult(str(path), fmt)
    path = Path(os.path.abspath(path))     # absolute (symlinks kept: the texture rules look at them)
    pkg, found = read_package(path, fmt, limits)
    if pkg is not None:
        found += shared_rules(pkg, limits, deep)
        if render_check is not None:
            found += guarded("render", path.name, _render, path, render_check)
    result.findings = ordered(found)
    result.seconds = time.perf_counter() - t0
    return result


def read_package(path: Path, fmt: str, limits: Limits) -> tuple[Package | None, list[Finding]]:
    """The format's reader and validators; (None, [file.unreadable]) when the file cannot be read."""
    if fmt == "unknown":
        return None, [finding(UNREADABLE, path.name, f"not a USD ({', '.join(USD_SUFFIXES)}) or glTF "
                              f"({', '.join(GLTF_SUFFIXES)}) file")]
    if not os.access(path, os.R_OK):
        return None, [finding(UNREADABLE, path.name, "permission denied")]
    try:
        regular_file(path)
    except DarthandError as e:          # a FIFO or device would block or never end: never opened
        return None, [finding(UNREADABLE, path.name, str(e).split(": ", 1)[-1])]
    try:
        if fmt in ("gltf", "glb"):
            return check_gltf(path, limits)
        from darthand.validate.rules_usd import read_usd  # lazy: OpenUSD takes 0.6 s to import, not for glTF files
        return read_usd(path, limits)
    except Exception as e:      # every reader failure, expected or not, is a finding naming the file
        return None, [finding(UNREADABLE, path.name, _reason(e))]


def _reason(e: Exception) -> str:
    from darthand.validate import usd_reader  # lazy: OpenUSD (0.6 s), already loaded when a USD file was read
    if isinstance(e, (usd_reader.Unreadable, gltf_reader.Unreadable, DarthandError)):
        return str(e)
    if isinstance(e, OSError):
        return e.strerror or str(e)
    return f"the reader failed ({type(e).__name__}: {e})"


def shared_rules(pkg: Package, limits: Limits, deep: bool) -> list[Finding]:
    out: list[Finding] = []
    for mesh in pkg.meshes:
        if mesh.layout_ok:
            out += guarded("mesh", mesh.path, check_mesh, mesh)
    out += guarded("rig", pkg.file.name, check_rig, pkg)
    out += guarded("texture", pkg.file.name, check_textures, pkg, limits, deep)
    out += guarded("accessory", pkg.file.name, check_accessories, pkg)
    return out


def guarded(family: str, where: str, fn, *args) -> list[Finding]:
    """fn(*args), with an exception turned into one finding (a rule must not stop the others)."""
    try:
        return fn(*args)
    except Exception as e:
        return [finding("file.malformed", where, f"the {family} rules could not run ({type(e).__name__}: {e})")]


def _render(path: Path, check) -> list[Finding]:
    return render_findings(path, check)


def ordered(findings: list[Finding]) -> list[Finding]:
    """Distinct findings, errors first, otherwise in the order the rules produced them."""
    unique = list(dict.fromkeys(findings))
    return sorted(unique, key=lambda f: SEVERITIES.index(f.severity))
