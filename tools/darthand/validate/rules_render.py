"""`--render`: render the asset with the reference renderer (darthand.render) and turn its checks into findings.

The renderer's checks (darthand.render.checks.check_package: render a few gestures, views, one accessory of each
kind and a UV checker, then check finiteness, coverage, keypoints on the mask, accessories next to their bone, UV
seams) need a USD package opened by darthand.render.api.open_source; the model it was built from is looked up as
<dir>/model/<side>.npz in the package's folder or up to three folders above (build/model/right.npz for
build/usd/right), for the fingertips. Each failed check becomes the finding `render.<check>` (error) with its first
failures as the message. glTF packages are not rendered (`render.unsupported`, info): the reference renderer reads
USD.

A check is a mapping {id, passed, message, severity?}; `render_findings` takes any function (path, out_dir) ->
checks, so the adapter is tested without rendering.

    render.failed        the renderer raised an error on the asset (e.g. it cannot open the package)
    render.unsupported   (info) the asset is not a USD package, so it was not rendered
"""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

from darthand.errors import DarthandError
from darthand.export.package_files import read_asset_info
from darthand.validate.findings import SEVERITIES, Finding, finding


RENDER_SIZE = 128           # pixels: enough for the checks' thresholds, about a second per package
SEARCH_DEPTH = 3


def renderer():
    """The check function (path, out_dir) -> checks of the reference renderer."""
    # lazy: the renderer (embreex, OpenImageIO, its kernels: ~1.2 s alone) only for `validate --render`
    from darthand.render.checks import check_package

    return lambda path, out_dir: package_checks(check_package, Path(path))


def package_checks(check_package, path: Path) -> list[dict]:
    """check_package on the USD package at `path`, as a list of {id, passed, message}."""
    if path.suffix.lower() in (".glb", ".gltf", ".usdz"):
        return [{"id": "unsupported", "passed": False, "severity": "info",
                 "message": "the reference renderer reads USD packages (a folder or its .usda), not this file"}]
    from darthand.render.api import open_source  # lazy: the renderer, as above

    source = open_source(path, model=nearby_model(path))
    result = check_package(source, size=RENDER_SIZE, all_accessories=False)
    return [{"id": name, "passed": bool(c.get("ok", True)), "message": "; ".join(map(str, c.get("failures", [])[:3]))}
            for name, c in result.get("checks", {}).items()]


def nearby_model(path: Path) -> Path | None:
    """<dir>/model/<side>.npz for the package's side, in its folder or up to SEARCH_DEPTH folders above."""
    folder = path if path.is_dir() else path.parent
    try:
        side = read_asset_info(folder).get("side", folder.name)
    except DarthandError:
        side = folder.name
    for base in [folder, *list(folder.parents)[:SEARCH_DEPTH]]:
        candidate = base / "model" / f"{side}.npz"
        if candidate.is_file():
            return candidate
    return None


def render_findings(path: Path, check=None) -> list[Finding]:
    """Render `path` into a temporary folder and return the failed checks as findings."""
    check = check or renderer()
    with tempfile.TemporaryDirectory(prefix="darthand-render-") as out_dir:
        try:
            results = list(check(path, Path(out_dir)))
        except DarthandError as e:
            return [finding("render.failed", path.name, str(e))]
        except Exception as e:       # a renderer bug must not become a traceback either
            return [finding("render.failed", path.name, f"the renderer failed ({type(e).__name__}: {e})")]
    out = []
    for item in results:
        if item.get("passed", True):
            continue
        name = re.sub(r"[^a-z0-9_.-]", "-", str(item.get("id", "check")).lower()).strip("-.") or "check"
        severity = str(item.get("severity", "error")).lower()
        out.append(finding(f"render.{name}", path.name, str(item.get("message") or "render check failed"),
                           severity if severity in SEVERITIES else "error"))
    return out
