"""Thin command functions for `darthand accessories ...` (the lead wires them into cli.py)."""

from __future__ import annotations

from darthand.accessories.build import build_accessories
from darthand.accessories.catalog import DEFAULT_SPEC, load_spec
from darthand.model.npz_io import load_npz


def build(args) -> int:
    """`darthand accessories build MODEL --out DIR [--spec catalog.json] [--ids ...] [--type ...]
    [--poses N] [--tolerance MM] [--no-refit] [--no-sheet]`: build the catalogue on a darthand model .npz."""
    model = load_npz(args.model)
    spec = load_spec(getattr(args, "spec", None) or DEFAULT_SPEC)
    catalog = build_accessories(model, spec, args.out, ids=getattr(args, "ids", None) or None,
                                types=getattr(args, "type", None) or None,
                                n_sampled=int(getattr(args, "poses", 300)),
                                tolerance_mm=float(getattr(args, "tolerance", 1.0)),
                                refit=not getattr(args, "no_refit", False), sheet=not getattr(args, "no_sheet", False))
    worst = max((a["max_penetration_mm"]["poses"] or 0.0 for a in catalog["accessories"]), default=0.0)
    print(f"[accessories] {len(catalog['accessories'])} built into {args.out} "
          f"(largest penetration across poses {worst:.2f} mm)")
    return 0


def add_parser(sub) -> None:
    """Register `accessories build` on an argparse subparsers object (for cli.py)."""
    g = sub.add_parser("accessories", help="fitted rings, watches, bracelets and gloves")
    gs = g.add_subparsers(title="accessories commands", metavar="COMMAND")
    p = gs.add_parser("build", help="fit, generate and verify the accessory catalogue on a model")
    p.add_argument("model", metavar="MODEL", help="wrist-enhanced darthand model .npz (build/model/right.npz)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (build/accessories)")
    p.add_argument("--spec", default=None, metavar="CATALOG.json", help="catalogue spec (default assets_src/accessories/catalog.json)")
    p.add_argument("--ids", nargs="+", default=None, metavar="ID", help="build only these accessory ids")
    p.add_argument("--type", nargs="+", default=None, choices=("ring", "watch", "bracelet", "glove"),
                   help="build only these types")
    p.add_argument("--poses", type=int, default=300, help="sampled anatomical poses in the verification sweep (default 300)")
    p.add_argument("--tolerance", type=float, default=1.0, help="penetration (mm) above which a rigid item is refitted")
    p.add_argument("--no-refit", action="store_true", help="report penetrations without refitting")
    p.add_argument("--no-sheet", action="store_true", help="skip the contact sheet")
    p.set_defaults(run=build)

