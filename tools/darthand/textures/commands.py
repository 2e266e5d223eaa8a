"""The `darthand textures ...` commands: each takes parsed arguments, calls the stage, prints a short report.

    textures build MODEL [--out DIR] [--res N] [--ids ID ...] [--category C ...] [--jobs N] [--no-tx]
                         [--no-roughness] [--no-sheet] [--force] [--spec PATH]      -> build
    textures sheet [--out DIR]                                                      -> sheet
    textures list [--spec PATH] [--category C ...] [--json]                        -> list_entries
    textures atlas MODEL --out OUT.npz [--res N]                                    -> atlas

`add_commands(group)` declares them on an argparse sub-parsers group (cli.py: `_group(sub, "textures", ...)`).
Each handler imports lazily what only it uses, so that building the CLI (and `darthand --help`) loads none of it.
"""

from __future__ import annotations

import collections
import json
import os
from pathlib import Path

from darthand.errors import InputError
from darthand.fileio import read_json


def _res(value) -> int:
    res = int(value if value is not None else os.environ.get("RES", 2048))
    if res < 16 or res > 16384 or res & (res - 1):
        raise InputError(f"--res: {res} must be a power of two between 16 and 16384")
    return res


def build(args) -> int:
    """Render the catalogue (or the --ids / --category subset) for MODEL into --out."""
    from darthand.model.load import load_model
    from darthand.textures.build import build_textures
    from darthand.textures.catalog import load_spec

    spec = load_spec(getattr(args, "spec", None))
    model = load_model(args.model)
    catalog = build_textures(model, spec, args.out, res=_res(getattr(args, "res", None)), ids=args.ids or None,
                             categories=args.category or None, workers=max(1, int(args.jobs)), progress=True,
                             tx=not args.no_tx, roughness=not getattr(args, "no_roughness", False),
                             sheet=not getattr(args, "no_sheet", False), force=getattr(args, "force", False))
    counts = collections.Counter(e["category"] for e in catalog["entries"])
    print(f"{len(catalog['entries'])} variants at {catalog['resolution']}x{catalog['resolution']} in "
          f"{Path(args.out) / 'catalog.json'}: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    return 0


def sheet(args) -> int:
    """Rebuild --out/contact_sheet.png from --out/catalog.json."""
    from darthand.textures.build import make_contact_sheet

    path = Path(args.out) / "catalog.json"
    catalog = read_json(path, "texture catalogue (run 'darthand textures build' first)")
    if not catalog.get("entries"):
        raise InputError(f"{path}: field 'entries' is empty; nothing to show")
    out = make_contact_sheet(args.out, catalog)
    print(f"{out}: {len(catalog['entries'])} thumbnails")
    return 0


def list_entries(args) -> int:
    """Print the catalogue's ids (per category), or every entry as JSON."""
    from darthand.textures.catalog import expand_catalog, load_spec, select

    entries = select(expand_catalog(load_spec(getattr(args, "spec", None))), None, args.category or None)
    if args.json:
        print(json.dumps([e.to_json() for e in entries], indent=2))
        return 0
    by_cat = collections.defaultdict(list)
    for e in entries:
        by_cat[e.category].append(e.id)
    for cat, ids in by_cat.items():
        print(f"{cat} ({len(ids)}): {ids[0]} .. {ids[-1]}")
    print(f"total {len(entries)}")
    return 0
