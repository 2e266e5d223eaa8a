"""glTF packages: the Khronos glTF-Validator (run by export.gltf_validator, when node and the npm package are
installed) and reading the package for the shared mesh, rig, texture and accessory rules (gltf_reader).

    gltf.<CODE>                  the validator's issues, one finding per code (with how many and the first
                                 JSON pointer); severities: errors -> error, warnings -> warning, infos and
                                 hints -> info
    gltf.validator-unavailable   (info) node or gltf-validator is not installed, or the validator failed to run
    gltf.buffer-path             a buffer URI is absolute, leads outside the package folder or names no file
"""

from __future__ import annotations

import re
from pathlib import Path

from darthand.errors import DarthandError
from darthand.export.gltf_validator import ValidatorUnavailable, validate
from darthand.validate.asset import Limits, Package
from darthand.validate.findings import Finding, finding
from darthand.validate.gltf_reader import read_gltf

KHRONOS_SEVERITY = ("error", "warning", "info", "info")
VALIDATOR_TIMEOUT = 120.0


def check_gltf(path: Path, limits: Limits = Limits()) -> tuple[Package, list[Finding]]:
    """Read the package (raises gltf_reader.Unreadable) and run the Khronos validator on it."""
    pkg, out = read_gltf(path, limits)
    return pkg, khronos_findings(path) + out


def khronos_findings(path: Path) -> list[Finding]:
    try:
        report = validate(path, timeout=VALIDATOR_TIMEOUT)
    except ValidatorUnavailable as e:
        return [finding("gltf.validator-unavailable", path.name, f"the Khronos glTF-Validator was not run: {e}")]
    except (DarthandError, OSError, ValueError) as e:       # node failed, timed out, or printed no JSON
        return [finding("gltf.validator-unavailable", path.name, f"the Khronos glTF-Validator failed: {e}")]
    except Exception as e:          # subprocess.TimeoutExpired and the like
        return [finding("gltf.validator-unavailable", path.name, f"the Khronos glTF-Validator failed: "
                        f"{type(e).__name__}: {e}")]
    grouped: dict[tuple[str, int], list[dict]] = {}
    for m in report.messages:
        grouped.setdefault((str(m.get("code", "UNKNOWN")), int(m.get("severity", 0))), []).append(m)
    out = []
    for (code, severity), messages in grouped.items():
        first = messages[0]
        more = f" ({len(messages)} times)" if len(messages) > 1 else ""
        rule = "gltf." + re.sub(r"[^A-Z0-9_]", "_", code.upper())
        out.append(finding(rule, first.get("pointer") or "/", f"{first.get('message', '')}{more}",
                           KHRONOS_SEVERITY[min(max(severity, 0), 3)]))
    return out
