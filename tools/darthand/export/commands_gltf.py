"""The `darthand export gltf | gltf-validate | blend` commands: each takes parsed arguments (cli.py defines them),
calls the stage, prints a short report. Each handler imports lazily what only it uses, so that
building the CLI (and `darthand --help`) loads none of it."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from darthand.errors import InputError
from darthand.accessories.loader import load_accessory_catalog
from darthand.export.influences import parse_influences
from darthand.export.shape_dials import DIAL_RANGE, dial_summary
from darthand.textures.loader import load_texture_catalog, select_textures


def gltf(args) -> int:
    """`darthand export gltf MODEL --out OUT.glb|OUT.gltf [--textures T [--texture ID ...] [--all-textures]]
    [--texture-size N] [--accessories A [--accessory ID ...]] [--influences K] [--correctives C]
    [--validate]`; prints a one-line summary. Exit 1 if --validate found errors."""
    from darthand.export.gltf_export import GltfOptions, export_gltf
    from darthand.model.load import load_model

    model = load_model(args.model)
    textures = []
    if args.textures:
        sets = load_texture_catalog(args.textures)
        textures = sets if args.all_textures else select_textures(sets, args.texture or [sets[0].id])
    elif args.texture or args.all_textures:
        raise InputError("--texture/--all-textures need --textures CATALOG.json")
    accessories = load_accessory_catalog(args.accessories, args.accessory, side=model.side) \
        if args.accessories else []
    options = GltfOptions(influences=parse_influences(args.influences), correctives=args.correctives,
                          texture_size=args.texture_size, shape_dials=getattr(args, "shape_dials", DIAL_RANGE))
    r = export_gltf(model, args.out, options=options, textures=textures, accessories=accessories)
    size = sum(Path(f).stat().st_size for f in r.files if Path(f).is_file())
    print(f"{args.out}: {model.side} hand, {r.vertices} glTF vertices ({r.model_vertices} model), "
          f"{r.influence_slots} influences (max error {1000 * r.influence_error_m:.2f} mm), "
          f"{r.morph_targets} morph "
          f"targets ({r.correctives}){dial_summary(r.shape_dials)}, {len(r.animations)} animations, "
          f"{max(1, len(r.variants))} textures, "
          f"{len(r.accessories)} accessories, {size / 1e6:.1f} MB")
    if not args.validate:
        return 0
    report = _validate(Path(args.out))
    print(f"Khronos glTF validator: {report.summary()}")
    return 1 if report.errors else 0


def blend(args) -> int:
    """`darthand export blend MODEL --out FILE.blend [--textures T]`: the Blender-native rig."""
    from darthand.export.blender_rig import export_blend
    from darthand.model.load import load_model

    model = load_model(args.model)
    texture = load_texture_catalog(args.textures)[0].albedo if args.textures else None
    info = export_blend(model, args.out, texture=texture)
    print(f"{args.out}: {model.side} hand, {info['shape_keys']} bone-driven corrective shape keys, "
          f"{len(info['gestures'])} gesture actions, {info['bytes'] / 1e6:.1f} MB")
    return 0


def validate(args) -> int:
    """`darthand export gltf-validate FILE ... [--json]`: the Khronos validator; exit 1 if any file has errors."""
    reports = [_validate(Path(p)) for p in args.paths]
    if args.json:
        print(json.dumps([{"path": r.path, "counts": r.counts, "messages": r.messages} for r in reports], indent=2))
    else:
        for r in reports:
            print(r.summary())
    return 1 if any(r.errors for r in reports) else 0


def _validate(path: Path):
    from darthand.export.gltf_validator import validate as run_validator

    if not path.is_file():
        raise InputError(f"{path}: no such file")
    report = run_validator(path)
    if report.errors:
        for m in report.issues("errors")[:20]:
            print(f"{path}: {m['code']} at {m.get('pointer', '')}: {m['message']}", file=sys.stderr)
    return report
