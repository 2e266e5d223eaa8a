"""OpenUSD's own validation of written stages and packages (UsdValidation: every registered validator).

UsdUtils.ComplianceChecker (usdchecker's old engine) is gone from usd-core 26; its checks (file extensions,
package encapsulation, usdz layout, missing references, stage metadata, material bindings, UsdSkel binding
rules, ...) are now validators in the registry, which is what runs here, on usdz packages too.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from pxr import Sdf, Usd, UsdValidation

from darthand.errors import InputError


@dataclass(frozen=True)
class Issue:
    """One validation finding: severity ('Error', 'Warn', 'Info'), validator name, message, sites (prim paths or
    layer identifiers), and the variant selection it was found under."""

    severity: str
    validator: str
    message: str
    sites: tuple[str, ...] = ()
    variants: tuple[tuple[str, str], ...] = ()

    def __str__(self) -> str:
        where = f" at {', '.join(self.sites)}" if self.sites else ""
        sel = f" [{', '.join(f'{k}={v}' for k, v in self.variants)}]" if self.variants else ""
        return f"{self.severity}: {self.validator}: {self.message}{where}{sel}"


_VALIDATORS = None


def all_validators() -> list:
    """Every validator the registry knows (loaded once per process)."""
    global _VALIDATORS
    if _VALIDATORS is None:
        _VALIDATORS = list(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    return _VALIDATORS


def validate_stage(stage: Usd.Stage, variants: tuple = (), skip=frozenset()) -> list[Issue]:
    """Every finding of every registered validator on `stage`, except the validators named in `skip`."""
    context = UsdValidation.ValidationContext([v for v in all_validators() if v.GetMetadata().name not in skip])
    issues = []
    for err in context.Validate(stage):
        if err.HasNoError():
            continue
        validator = err.GetValidator()
        issues.append(Issue(str(err.GetType()).rsplit(".", 1)[-1], validator.GetMetadata().name if validator else
                            err.GetName(), err.GetMessage(), tuple(_site(s) for s in err.GetSites()), variants))
    return issues


def validate_file(path: str | os.PathLike, selections: dict[str, str] | None = None) -> list[Issue]:
    """Open `path` (a layer or a .usdz) with everything loaded, optionally with variant selections on its default
    prim (set in a session layer, the file is not changed), and validate it."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such USD file")
    stage = Usd.Stage.Open(str(path), Usd.Stage.LoadAll)
    if stage is None:
        raise InputError(f"{path}: not a readable USD stage")
    if selections:
        select_variants(stage, selections)
    return validate_stage(stage, tuple(sorted((selections or {}).items())))


def validate_variants(path: str | os.PathLike) -> list[Issue]:
    """Validate the asset once per variant of each variant set on its default prim (the other sets at their
    default selection): every variant's layer is composed and checked at least once."""
    stage = Usd.Stage.Open(str(path), Usd.Stage.LoadAll)
    prim = stage.GetDefaultPrim()
    issues = validate_stage(stage)
    for set_name in prim.GetVariantSets().GetNames():
        vset = prim.GetVariantSets().GetVariantSet(set_name)
        default = vset.GetVariantSelection()
        for name in vset.GetVariantNames():
            if name != default:
                issues += validate_file(path, {set_name: name})
    return issues


def select_variants(stage: Usd.Stage, selections: dict[str, str]) -> None:
    """Select variants on the default prim in the stage's session layer; unknown sets or names are an InputError."""
    prim = stage.GetDefaultPrim()
    with Usd.EditContext(stage, stage.GetSessionLayer()):
        for set_name, name in selections.items():
            vsets = prim.GetVariantSets()
            if not vsets.HasVariantSet(set_name):
                raise InputError(f"{stage.GetRootLayer().identifier}: {prim.GetPath()} has no variant set "
                                 f"{set_name!r} (has {', '.join(vsets.GetNames()) or 'none'})")
            vset = vsets.GetVariantSet(set_name)
            if name not in vset.GetVariantNames():
                raise InputError(f"{stage.GetRootLayer().identifier}: variant set {set_name!r} has no variant "
                                 f"{name!r}")
            vset.SetVariantSelection(name)


def errors(issues: list[Issue]) -> list[Issue]:
    return [i for i in issues if i.severity == "Error"]


def _site(site) -> str:
    if site.IsPrim():
        return str(site.GetPrim().GetPath())
    if site.IsProperty():
        return str(site.GetProperty().GetPath())
    layer = site.GetLayer()
    return layer.identifier if isinstance(layer, Sdf.Layer) else ""
