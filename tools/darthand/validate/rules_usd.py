"""USD packages: OpenUSD's own validators (the UsdValidation registry, run by export.usd_validate) over the asset
and each of its variants, the package's layers staying inside its folder, and reading the package for the shared
mesh, rig, texture and accessory rules.

What is composed and checked:

- the asset as it opens (default variant selections, payloads loaded): every validator, every rule;
- each other variant of every variant set on the default prim:
    `texture` variants whose content comes from referenced layers (texture/<id>.usda) are checked layer by layer:
    each layer opened as its own stage (validators and texture rules; the stage-metadata validators are left out,
    since a referenced layer's metadata does not govern the asset), which is ~10x cheaper than recomposing the
    asset per texture and matters with 325 of them;
    every other variant (accessories, or texture variants with inline content) recomposes the asset with that
    selection: the validators whose verdict depends on the composition (all but ROOT_LAYER_VALIDATORS, which judge
    the root layer and all its dependencies, every variant's included, and ran on the asset as it opens) on the
    whole composition, findings already seen not repeated; mesh, rig, texture and accessory rules on what the
    variant adds.

Paths of findings inside a variant use USD's variant-selection syntax, e.g.
`/RightHand{accessory=ring_01}RightHandAccessory/Right_ring_01`.

    usd.<validator name>        a finding of that OpenUSD validator (severity Error / Warn / Info as it reports)
    usd.layer-outside-package   a layer the asset composes lies outside the package folder (absolute or '..'
                                arcs, or a symlinked layer)
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from pxr import Ar, Sdf, Tf, Usd

from darthand.errors import DarthandError
from darthand.export.package_files import ASSET_INFO, Problem, read_asset_info, usd_problems
from darthand.export.usd_validate import validate_stage
from darthand.validate.asset import Limits, Package
from darthand.validate.findings import UNREADABLE, Finding, finding
from darthand.validate.usd_reader import (Unreadable, open_stage, read_meshes, read_skeletons, read_textures,
                                          tf_message)

LAYERED_SETS = ("texture",)
METADATA_VALIDATORS = frozenset({"usdValidation:StageMetadataChecker", "usdGeomValidators:StageMetadataChecker"})
# Validators that judge the root layer and everything it depends on (every variant's layers included) or its
# metadata: their verdict does not change with the variant selection, so they run once, on the asset as it opens
# (MissingReferenceValidator and UsdzPackageValidator alone cost ~70 ms each per run on the open hand's package).
ROOT_LAYER_VALIDATORS = METADATA_VALIDATORS | {
    "usdUtilsValidators:MissingReferenceValidator", "usdUtilsValidators:UsdzPackageValidator",
    "usdUtilsValidators:PackageEncapsulationValidator", "usdUtilsValidators:RootPackageValidator",
    "usdUtilsValidators:FileExtensionValidator"}
SEVERITY = {"Error": "error", "Warn": "warning", "Info": "info"}


def read_usd(path: Path, limits: Limits = Limits()) -> tuple[Package | None, list[Finding]]:
    """The package of a .usda/.usdc/.usd/.usdz file and the USD findings; (None, findings) when the package refers
    to layers that must not be opened (outside the package, links leaving it, FIFOs and other non-regular files:
    export.package_files), which are reported without composing anything. Raises Unreadable when the file cannot
    be opened at all."""
    usdz = path.suffix.lower() == ".usdz"
    info, found = ({}, []) if usdz else asset_info(path.parent)
    pkg = Package(path, "usdz" if usdz else "usd", path if usdz else path.parent, side=info.get("side"))
    with Tf.DiagnosticTrap() as trap:    # USD's warnings become findings (or are repeats of them), not stderr noise
        try:
            blocked = [p for p in usd_problems(path, pkg.root) if p.role == "layer"]
            if blocked:
                return None, found + [layer_finding(p) for p in blocked]
            claims = (info.get("options") or {}).get("correctives") == "full"
            return pkg, found + UsdCheck(path, pkg, limits, claims).run()
        finally:
            trap.Clear()


def layer_finding(problem: Problem) -> Finding:
    """A layer that is not opened: outside the package (or a link leaving it), or not a regular file."""
    rule = "usd.layer-outside-package" if "outside" in problem.reason else UNREADABLE
    return finding(rule, problem.where, f"the asset composes @{problem.asset}@, which {problem.reason}; the "
                   "package is not opened")


def asset_info(folder: Path) -> tuple[dict, list[Finding]]:
    """darthand's asset.json beside the layer ({} when absent; optional for the rules) and a file.malformed
    finding when it is there but not a sound asset.json."""
    try:
        return read_asset_info(folder), []
    except DarthandError as e:
        return {}, [finding("file.malformed", ASSET_INFO, str(e).split(": ", 1)[-1])]


class UsdCheck:
    """One package's USD checks; keeps the validator findings already reported and the layers already seen."""

    def __init__(self, path: Path, pkg: Package, limits: Limits, claims_correctives: bool):
        self.path, self.pkg, self.limits, self.claims = path, pkg, limits, claims_correctives
        self.seen: set[tuple[str, str, str]] = set()
        self.layers: set[str] = set()

    def run(self) -> list[Finding]:
        stage = open_stage(self.path)
        out = self.validators(stage, str) + self.layers_outside(stage)
        prim = stage.GetDefaultPrim()
        selection = prim.GetVariantSets().GetVariantSelection("accessory") if prim else ""
        out += read_skeletons(stage, self.pkg, str, self.limits)
        out += read_meshes(stage, self.pkg, str, self.limits, accessory_id=selection or None,
                           claims_correctives=self.claims)
        read_textures(stage, self.pkg, str)
        if prim:
            out += self.variants(stage, prim)
        return out

    # -------------------------------------------------------------------------------------------- validators

    def validators(self, stage: Usd.Stage, label, skip=frozenset()) -> list[Finding]:
        """OpenUSD's validators on `stage`, each distinct (validator, site, message) reported once."""
        out = []
        try:
            issues = validate_stage(stage, skip=skip)
        except Tf.ErrorException as e:     # a validator opened a layer that does not parse
            return self.unparsable_layers(stage, label) or [
                finding(UNREADABLE, self.path.name, f"OpenUSD's validators stopped: {tf_message(e)}")]
        for issue in issues:
            site = issue.sites[0] if issue.sites else ""
            key = (issue.validator, site, issue.message)
            if key in self.seen:
                continue
            self.seen.add(key)
            rule = "usd." + re.sub(r"[^A-Za-z0-9_:]", "_", issue.validator)
            out.append(finding(rule, self.site_label(site, label), issue.message,
                               SEVERITY.get(issue.severity, "error")))
        return out

    def unparsable_layers(self, stage: Usd.Stage, label) -> list[Finding]:
        """file.unreadable for each layer the composition could not open because it does not parse (a missing
        layer is the validators' business, which they report when they can run)."""
        out = []
        for error in stage.GetCompositionErrors():
            text = str(error)
            asset = re.search(r"@([^@]+)@", text)
            if "Could not open asset" in text and asset and os.path.isfile(asset.group(1)):
                out.append(finding(UNREADABLE, self.file_label(asset.group(1)), text))
        return out

    def site_label(self, site: str, label) -> str:
        if site.startswith("/") and Sdf.Path.IsValidPathString(site) and not os.path.exists(site):
            return label(Sdf.Path(site))
        return self.file_label(site) if site else str(self.path.name)

    def file_label(self, path: str) -> str:
        try:
            return Path(path).resolve().relative_to(self.pkg.root.resolve()).as_posix()
        except (ValueError, OSError):
            return path

    def layers_outside(self, stage: Usd.Stage) -> list[Finding]:
        out = []
        root = os.path.realpath(self.pkg.root)
        for layer in stage.GetUsedLayers():
            if layer.anonymous or layer.identifier in self.layers:
                continue
            self.layers.add(layer.identifier)
            if self.pkg.format == "usdz":
                outer = Ar.SplitPackageRelativePathOuter(layer.identifier)[0] \
                    if Ar.IsPackageRelativePath(layer.identifier) else layer.realPath
                inside = os.path.realpath(outer) == root
            else:
                real = os.path.realpath(layer.realPath)
                inside = real == root or real.startswith(root + os.sep)
            if not inside:
                out.append(finding("usd.layer-outside-package", self.file_label(layer.identifier),
                                   f"the asset composes layer {layer.identifier}, outside the package "
                                   f"{self.pkg.root}"))
        return out

    # -------------------------------------------------------------------------------------------- variants

    def variants(self, stage: Usd.Stage, prim: Usd.Prim) -> list[Finding]:
        out, layered = [], []
        root = prim.GetPath()
        vsets = prim.GetVariantSets()
        for set_name in vsets.GetNames():
            vset = vsets.GetVariantSet(set_name)
            default = vset.GetVariantSelection()
            for name in vset.GetVariantNames():
                self.record_id(root, set_name, name)
                if name == default:
                    continue
                arcs = variant_arcs(prim, set_name, name)
                if set_name in LAYERED_SETS and arcs and all(a[3] for a in arcs):
                    layered += arcs
                else:       # composing reports why a variant layer does not resolve
                    out += self.composed_variant(root, set_name, name, arcs)
        return out + (self.layered_variants(layered) if layered else [])

    def record_id(self, root: Sdf.Path, set_name: str, name: str) -> None:
        where = f"{root}{{{set_name}={name}}}"
        if set_name == "texture":
            self.pkg.texture_ids.append((name, where))
        elif set_name == "accessory" and name != "none":
            self.pkg.accessory_ids.append((name, where))

    def layered_variants(self, arcs) -> list[Finding]:
        """The variants' layers composed side by side, each referenced by one prim of an in-memory stage, checked
        in one pass (one stage per layer costs ~1 ms each, which adds up over 325 textures). The root-layer
        validators are left out: the in-memory root is not the asset's, and they ran on the asset's."""
        stage = Usd.Stage.CreateInMemory()
        holders = {}
        with Sdf.ChangeBlock():
            for k, (spec_path, _, _, layer_path, prim_path) in enumerate(arcs):
                holder = Sdf.CreatePrimInLayer(stage.GetRootLayer(), f"/Variant{k}")
                holder.specifier = Sdf.SpecifierDef
                holder.referenceList.Prepend(Sdf.Reference(layer_path, prim_path))
                holders[holder.path] = spec_path

        def label(p: Sdf.Path) -> str:
            top = p.GetPrefixes()[0] if p.IsAbsolutePath() and p != Sdf.Path.absoluteRootPath else None
            return str(p.ReplacePrefix(top, holders[top])) if top in holders else str(p)

        return self.validators(stage, label, skip=ROOT_LAYER_VALIDATORS) + self.layers_outside(stage) + \
            read_textures(stage, self.pkg, label)

    def composed_variant(self, root: Sdf.Path, set_name: str, name: str, arcs) -> list[Finding]:
        try:
            sub = open_stage(self.path, {set_name: name})
        except Unreadable as e:
            return [finding("file.malformed", f"{root}{{{set_name}={name}}}",
                            f"the asset does not open with this variant: {e}")]
        label = _variant_label(root, set_name, name)
        out = self.validators(sub, label, skip=ROOT_LAYER_VALIDATORS) + self.layers_outside(sub)
        tops = sorted({a[0].StripAllVariantSelections() for a in arcs}) or [root]
        for top in tops:
            out += read_meshes(sub, self.pkg, label, self.limits, under=top,
                               accessory_id=name if set_name == "accessory" else None)
            read_textures(sub, self.pkg, label, under=top)
        return out


def variant_arcs(prim: Usd.Prim, set_name: str, name: str) -> list[tuple]:
    """(spec path in the variant, layer, authored asset path, resolved layer path or '', target prim path) of every
    reference and payload the variant authors, over the prim's specs in all layers."""
    arcs = []
    for spec in prim.GetPrimStack():
        vset = spec.variantSets.get(set_name)
        variant = vset.variants.get(name) if vset is not None else None
        if variant is None:
            continue
        todo = [variant.primSpec]
        while todo:
            s = todo.pop()
            todo += list(s.nameChildren)
            for item in list(s.referenceList.GetAddedOrExplicitItems()) + list(s.payloadList.GetAddedOrExplicitItems()):
                if not item.assetPath:
                    continue
                resolved = Sdf.ComputeAssetPathRelativeToLayer(spec.layer, item.assetPath)
                exists = bool(resolved) and (os.path.isfile(resolved) or Ar.IsPackageRelativePath(resolved))
                arcs.append((s.path, spec.layer, item.assetPath, resolved if exists else "", item.primPath))
    return arcs


def _variant_label(root: Sdf.Path, set_name: str, name: str):
    """Label prims of a composition under a variant selection: /RightHand/X -> /RightHand{set=name}X."""
    selected = root.AppendVariantSelection(set_name, name)

    def label(p: Sdf.Path) -> str:
        if p.HasPrefix(root) and p != root:
            rel = p.MakeRelativePath(root)
            return str(selected) + str(rel)
        return str(p)
    return label
