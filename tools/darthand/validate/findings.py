"""What a validation finds: `Finding` (rule id, severity, where, one-line message), the rule table, and the
`Report` over all checked packages with its exit code.

Rule ids are stable: `<family>.<name>` for darthand's own rules (the table `RULES`, also in rules.md and in
schemas/validation_report.schema.json), `usd.<validator name>` for OpenUSD's validators (their registry names,
e.g. `usd.usdSkelValidators:SkelBindingApiValidator`), `gltf.<CODE>` for the Khronos glTF-Validator's issue codes
(e.g. `gltf.ACCESSOR_WEIGHTS_NON_NORMALIZED`) and `render.<check>` for the reference renderer's checks.

Exit codes: 2 when a package could not be read (a `file.unreadable` finding), else 1 when any finding is an error,
else 0 (warnings and infos are reported but do not fail a package).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

SEVERITIES = ("error", "warning", "info")
UNREADABLE = "file.unreadable"


@dataclass(frozen=True)
class Rule:
    severity: str
    summary: str


RULES: dict[str, Rule] = {
    # files and limits
    UNREADABLE: Rule("error", "the file cannot be read: missing, truncated, not USD/glTF, or its parser failed"),
    "file.array-too-large": Rule("error", "an array is larger than the validator's limit; that part is not checked"),
    "file.malformed": Rule("error", "arrays are inconsistent (counts, lengths, offsets past the end of a buffer)"),
    "usd.layer-outside-package": Rule("error", "a layer the asset composes lies outside the package folder"),
    "gltf.buffer-path": Rule("error", "a glTF buffer URI is absolute, leads outside the package or names no file"),
    "gltf.validator-unavailable": Rule("info", "the Khronos glTF-Validator (node + npm ci) is not installed"),
    # rig
    "rig.no-skeleton": Rule("error", "no skeleton (UsdSkel Skeleton / glTF skin) is bound to the hand"),
    "rig.no-skin": Rule("error", "the hand mesh has no joint influences"),
    "rig.joint-count": Rule("error", "the skeleton does not have MANO's 16 joints"),
    "rig.hierarchy": Rule("error", "the joint parents differ from MANO's"),
    "rig.joint-names": Rule("warning", "the joint names differ from MANO's (wrist, index1, ...)"),
    "rig.bind-transform": Rule("error", "a bind transform is not rigid (an orthonormal rotation with det +1 and a "
                                        "translation)"),
    "rig.rest-transform": Rule("error", "a rest transform is not rigid"),
    "rig.bind-rest-mismatch": Rule("error", "bind transforms are not the composition of the rest transforms"),
    "rig.skin-layout": Rule("error", "joint indices and weights have inconsistent sizes or interpolation"),
    "rig.joint-index": Rule("error", "a joint index is outside the skeleton"),
    "rig.weights-nonfinite": Rule("error", "a skin weight is NaN or infinite"),
    "rig.weights-negative": Rule("error", "a skin weight is negative"),
    "rig.weights-sum": Rule("error", "a point's skin weights do not sum to 1 within 1e-6"),
    "rig.blendshape-layout": Rule("error", "blend-shape names, targets, offsets and point indices do not match up"),
    "rig.blendshape-nonfinite": Rule("error", "a blend-shape offset is NaN or infinite"),
    "rig.blendshape-index": Rule("error", "a blend-shape point index is outside the mesh"),
    "rig.blendshape-duplicate-index": Rule("error", "a blend shape lists a point index twice"),
    "rig.correctives-missing": Rule("error", "correctives are claimed but the shapes (pose_<joint>_rRC_pos/neg) "
                                             "of some of the 135 channels are missing"),
    # mesh
    "mesh.nonfinite-point": Rule("error", "a point is NaN or infinite"),
    "mesh.face-index": Rule("error", "a face indexes a point outside the mesh"),
    "mesh.degenerate-face": Rule("error", "a face has zero area (repeated or collinear corners)"),
    "mesh.duplicate-face": Rule("error", "two faces use the same points"),
    "mesh.non-manifold-edge": Rule("error", "an edge is shared by more than two faces"),
    "mesh.open-boundary": Rule("error", "the hand has an open boundary besides the forearm opening"),
    "mesh.winding": Rule("error", "neighbouring faces are wound in opposite directions"),
    "mesh.uv-index": Rule("error", "a face corner indexes a UV outside the UV array"),
    "mesh.uv-nonfinite": Rule("error", "a UV is NaN or infinite"),
    "mesh.uv-range": Rule("error", "a UV used by a face lies outside [0, 1]"),
    # textures
    "tex.absolute-path": Rule("error", "a texture path is absolute"),
    "tex.path-escapes": Rule("error", "a texture path leads outside the package folder ('..')"),
    "tex.symlink-outside": Rule("error", "a texture file is a symlink resolving outside the package folder"),
    "tex.missing": Rule("error", "a texture file does not exist"),
    "tex.unreadable": Rule("error", "a texture file cannot be read or is corrupt (truncated, bad chunks)"),
    "tex.not-power-of-two": Rule("error", "a texture's width or height is not a power of two"),
    "tex.albedo-colorspace": Rule("error", "an albedo / colour texture is not read as sRGB"),
    "tex.data-colorspace": Rule("error", "a data map (roughness, metallic, normal, ...) is not read as raw"),
    "tex.unknown-id": Rule("error", "a texture variant id is not in the texture catalogue"),
    # accessories
    "acc.binding": Rule("error", "an accessory is neither bound to one joint (rigid) nor skinned"),
    "acc.bad-joint": Rule("error", "a rigid accessory is bound to a joint the skeleton does not have"),
    "acc.distance": Rule("error", "an accessory is more than a few millimetres from the hand surface at rest"),
    "acc.unknown-id": Rule("error", "an accessory id is not in the accessory catalogue"),
    # render
    "render.failed": Rule("error", "the reference renderer could not render the asset"),
    "render.unsupported": Rule("info", "the asset is not a USD package, so the reference renderer did not render it"),
}

@dataclass(frozen=True)
class Finding:
    """One problem: `rule` id, `severity` (error | warning | info), `path` (prim path, glTF JSON pointer or file
    inside the package) and a one-line `message`."""

    rule: str
    severity: str
    path: str
    message: str

    def as_dict(self) -> dict:
        return asdict(self)


def finding(rule: str, path: str, message: str, severity: str | None = None) -> Finding:
    """A finding of one of darthand's rules, at the rule's severity unless given (external rules must give it)."""
    if severity is None:
        severity = RULES[rule].severity
    if severity not in SEVERITIES:
        raise ValueError(f"severity {severity!r} is not one of {SEVERITIES}")
    return Finding(rule, severity, str(path), " ".join(str(message).split()))


def examples(indices, limit: int = 5) -> str:
    """'3, 17, 40' or '3, 17, 40, 41, 52, ... (12 in all)' for messages."""
    items = [int(i) for i in list(indices)[: limit + 1]]
    text = ", ".join(map(str, items[:limit]))
    total = len(indices)
    return text + (f", ... ({total} in all)" if total > limit else "")


def counts(findings) -> dict[str, int]:
    out = {s: 0 for s in SEVERITIES}
    for f in findings:
        out[f.severity] += 1
    return out


@dataclass
class PackageResult:
    """The findings on one checked file. format: usd | usdz | gltf | glb | unknown."""

    path: str
    format: str
    findings: list[Finding] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def unreadable(self) -> bool:
        return any(f.rule == UNREADABLE for f in self.findings)

    @property
    def status(self) -> str:
        if self.unreadable:
            return "unreadable"
        return "problems" if any(f.severity == "error" for f in self.findings) else "clean"

    @property
    def exit_code(self) -> int:
        return {"unreadable": 2, "problems": 1, "clean": 0}[self.status]

    def as_dict(self) -> dict:
        return {"path": self.path, "format": self.format, "status": self.status,
                "seconds": round(self.seconds, 4), "counts": counts(self.findings),
                "findings": [f.as_dict() for f in self.findings]}


@dataclass
class Report:
    """Every checked package; exit code 2 if one was unreadable, else 1 if one had errors, else 0."""

    packages: list[PackageResult] = field(default_factory=list)

    @property
    def findings(self) -> list[Finding]:
        return [f for p in self.packages for f in p.findings]

    @property
    def exit_code(self) -> int:
        return max((p.exit_code for p in self.packages), default=0)

    def as_dict(self) -> dict:
        return {"format": "darthand-validation-report", "version": 1, "exit_code": self.exit_code,
                "counts": counts(self.findings), "packages": [p.as_dict() for p in self.packages]}
