"""Thin command functions for `darthand objects ...` (arguments are defined in cli.py)."""

from __future__ import annotations

from pathlib import Path

from darthand.fileio import make_folder
from darthand.objects.build import build_objects
from darthand.objects.catalog import DEFAULT_SPEC, load_spec


def build(args) -> int:
    """`darthand objects build --out DIR [--spec catalog.json] [--ids ...] [--jobs N] [--no-sheet]`: generate,
    import and check the object catalogue."""
    spec_path = Path(getattr(args, "spec", None) or DEFAULT_SPEC)
    spec = load_spec(spec_path)
    make_folder(args.out)
    catalog = build_objects(spec, args.out, spec_path.parent, ids=getattr(args, "ids", None) or None,
                            jobs=int(getattr(args, "jobs", 1) or 1), sheet=not getattr(args, "no_sheet", False),
                            source=str(spec_path))
    objects = catalog["objects"]
    categories = sorted({o["category"] for o in objects})
    line = f"[objects] {len(objects)} objects in {len(categories)} categories built into {args.out}"
    if catalog["skipped"]:
        line += f"; {len(catalog['skipped'])} skipped:"
        line += "".join(f"\n  {s['id']}: {s['why']}" for s in catalog["skipped"])
    print(line)
    return 0
