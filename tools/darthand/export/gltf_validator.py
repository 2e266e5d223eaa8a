"""Run the Khronos glTF-Validator (npm package `gltf-validator`, installed at the repo root by `npm ci`) on a file.

The validator is the reference implementation of the spec's rules; it runs in Node, so this module starts one
`node` process per file with a short script that reads the asset (and, for .gltf, its external buffers and images
relative to it), validates it and prints the JSON report, which is parsed into a `ValidationReport`.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

from darthand.errors import DarthandError
from darthand.fileio import regular_file

REPO_ROOT = Path(__file__).resolve().parents[3]
PACKAGE = "gltf-validator"
SEVERITIES = ("errors", "warnings", "infos", "hints")  # the report's severity codes 0..3

_SCRIPT = r"""
const fs = require("fs");
const path = require("path");
const validator = require(process.argv[1]);
const file = process.argv[2];
const maxIssues = parseInt(process.argv[3], 10);
const root = fs.realpathSync(path.dirname(file));
// Only relative URIs naming a regular file inside the asset's folder (links resolved) are read: a URI of an
// untrusted asset must not make the validator read anything else, or block on a FIFO.
function packageFile(uri) {
  const rel = decodeURIComponent(uri);
  if (/^[A-Za-z][A-Za-z0-9+.-]+:/.test(rel) || path.isAbsolute(rel)) { throw "absolute URI, not read"; }
  const target = fs.realpathSync(path.resolve(path.dirname(file), rel));
  if (!target.startsWith(root + path.sep)) { throw "outside the asset's folder, not read"; }
  if (!fs.statSync(target).isFile()) { throw "not a regular file, not read"; }
  return target;
}
validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
  uri: path.basename(file),
  maxIssues: maxIssues,
  writeTimestamp: false,
  externalResourceFunction: (uri) => new Promise((resolve, reject) => {
    let target;
    try { target = packageFile(uri); } catch (e) { reject(`${uri}: ${e}`); return; }
    fs.readFile(target, (err, data) => {
      if (err) { reject(err.toString()); } else { resolve(new Uint8Array(data)); }
    });
  }),
}).then((report) => { process.stdout.write(JSON.stringify(report)); },
        (error) => { process.stderr.write(String(error)); process.exit(3); });
"""


class ValidatorUnavailable(DarthandError):
    """Node or a needed npm package (gltf-validator, three) is not installed."""


@dataclass
class ValidationReport:
    """The validator's verdict on one file: counts per severity and the issues themselves."""

    path: str
    validator_version: str
    counts: dict                      # {"errors": n, "warnings": n, "infos": n, "hints": n}
    messages: list = field(default_factory=list)   # [{"code", "message", "severity", "pointer"}]
    info: dict = field(default_factory=dict)       # the report's asset summary (counts of meshes, animations, ...)

    @property
    def errors(self) -> int:
        return self.counts["errors"]

    def issues(self, severity: str = "errors") -> list[dict]:
        """The messages of one severity ('errors', 'warnings', 'infos', 'hints')."""
        level = SEVERITIES.index(severity)
        return [m for m in self.messages if m.get("severity") == level]

    def summary(self) -> str:
        """One line: counts, then the distinct codes of errors and warnings."""
        codes = sorted({m["code"] for m in self.messages if m.get("severity", 9) <= 1})
        counts = ", ".join(f"{self.counts[s]} {s}" for s in SEVERITIES)
        return f"{self.path}: {counts}" + (f" ({', '.join(codes)})" if codes else "")


def node_package(name: str, root: Path = REPO_ROOT) -> Path:
    """The folder of an npm package installed at the repo root; ValidatorUnavailable naming the fix when node or
    the package is missing."""
    if shutil.which("node") is None:
        raise ValidatorUnavailable(f"node is not installed: {name} needs Node.js (then `npm ci` at the repo root)")
    pkg = root / "node_modules" / name
    if not (pkg / "package.json").is_file():
        raise ValidatorUnavailable(f"{pkg}: the npm package {name} is not installed; run `npm ci` in {root}")
    return pkg


def validator_package(root: Path = REPO_ROOT) -> Path:
    """The installed gltf-validator package folder (see `node_package`)."""
    return node_package(PACKAGE, root)


def validate(path: str | Path, *, max_issues: int = 0, timeout: float = 600.0) -> ValidationReport:
    """Validate a .glb or .gltf (with its external resources) and return the parsed report.

    max_issues: cap on reported issues (0: all). Raises ValidatorUnavailable if the validator is not installed and
    DarthandError if it could not read the file at all.
    """
    path = Path(path).resolve()
    regular_file(path, "glTF file")       # node would block on a FIFO
    pkg = validator_package()
    env = dict(os.environ, NODE_OPTIONS="--max-old-space-size=4096")
    proc = subprocess.run(["node", "-e", _SCRIPT, str(pkg), str(path), str(max_issues)], capture_output=True,
                          text=True, timeout=timeout, env=env)
    if proc.returncode != 0:
        raise DarthandError(f"{path}: glTF validator failed: {proc.stderr.strip()[:500]}")
    report = json.loads(proc.stdout)
    issues = report.get("issues", {})
    counts = {s: int(issues.get(f"num{s.capitalize()}", 0)) for s in SEVERITIES}
    return ValidationReport(str(path), report.get("validatorVersion", ""), counts, issues.get("messages", []),
                            report.get("info", {}))
