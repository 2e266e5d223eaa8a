"""The `darthand export usd | usdz | usd-check` commands: each takes parsed arguments (cli.py defines them), calls
the stage, prints a short report."""

from __future__ import annotations

from pathlib import Path

from darthand.accessories.loader import load_accessory_catalog
from darthand.export.influences import parse_influences
from darthand.export.shape_dials import DIAL_RANGE, dial_summary
from darthand.export.usd_asset import ExportOptions, export_usd
from darthand.export.usd_validate import errors, validate_file, validate_variants
from darthand.export.usdz import export_usdz, interface_layer
from darthand.model.load import load_model
from darthand.textures.loader import load_texture_catalog


def usd(args) -> int:
    """`darthand export usd MODEL --out DIR [--textures T] [--accessories A] [--influences K] [--correctives C]
    [--texture-size N] [--name NAME]`. A model without UVs (a raw MANO pkl) gets them from `model build`."""
    model = load_model(args.model)
    if "wrist" not in model.meta:
        print(f"  note: {args.model} has no DART wrist (the pipeline exports build/model/<side>.npz, which has)")
    textures = load_texture_catalog(args.textures) if args.textures else []
    accessories = load_accessory_catalog(args.accessories, side=model.side) if args.accessories else []
    options = ExportOptions(influences=parse_influences(args.influences), correctives=args.correctives,
                            texture_size=args.texture_size, shape_dials=getattr(args, "shape_dials", DIAL_RANGE))
    info = export_usd(model, args.out, textures=textures, accessories=accessories, options=options, name=args.name)
    rig = info["rig"]
    size = sum(info["files"].values())
    print(f"{Path(args.out) / info['interface']}: {model.side} hand, {info['model']['vertices']} vertices, "
          f"{rig['influences']} influences, {rig['blend_shapes']} blend shapes "
          f"({options.correctives}{dial_summary(info['shape_dials'], ' incl.')}), "
          f"{len(rig['gestures'])} gestures, {len(info['variants']['texture'])} textures, "
          f"{len(info['variants']['accessory']) - 1} accessories, {size / 1e6:.1f} MB, {info['write_seconds']} s")
    return 0


def usdz(args) -> int:
    """`darthand export usdz PACKAGE --out FILE.usdz [--texture ID] [--accessory ID]`."""
    files = export_usdz(args.package, args.out, texture=args.texture, accessory=args.accessory)
    print(f"{args.out}: {len(files)} files ({files[0]} + {len(files) - 1} textures), "
          f"{Path(args.out).stat().st_size / 1e6:.1f} MB")
    return 0


def check(args) -> int:
    """`darthand export usd-check PACKAGE|FILE [--all-variants]`: OpenUSD's validators; exit 1 on any error."""
    path = interface_layer(args.package)
    issues = validate_variants(path) if args.all_variants else validate_file(path)
    for issue in issues:
        print(issue)
    bad = errors(issues)
    print(f"{path}: {len(bad)} errors, {len(issues) - len(bad)} other findings")
    return 1 if bad else 0
