"""Thin command functions for `darthand accessories ...` (arguments are defined in cli.py)."""

from __future__ import annotations

from darthand.accessories.build import build_accessories
from darthand.accessories.catalog import DEFAULT_SPEC, load_spec
from darthand.model.npz_io import load_npz


def build(args) -> int:
    """`darthand accessories build MODEL --out DIR [--spec catalog.json] [--ids ...] [--type ...]
    [--poses N] [--tolerance MM] [--no-refit] [--no-sheet] [--jobs N]`: build the catalogue on a darthand model .npz."""
    model = load_npz(args.model)
    spec = load_spec(getattr(args, "spec", None) or DEFAULT_SPEC)
    catalog = build_accessories(model, spec, args.out, ids=getattr(args, "ids", None) or None,
                                types=getattr(args, "type", None) or None,
                                n_sampled=int(getattr(args, "poses", 300)),
                                tolerance_mm=float(getattr(args, "tolerance", 1.0)),
                                refit=not getattr(args, "no_refit", False), sheet=not getattr(args, "no_sheet", False),
                                workers=int(getattr(args, "jobs", 1) or 1))
    pens = [a["max_penetration_mm"] for a in catalog["accessories"]]
    worst = max((p["poses"] or 0.0 for p in pens), default=0.0)
    fit = max(((p["fit_poses"] if "fit_poses" in p else p["poses"]) or 0.0 for p in pens), default=0.0)
    print(f"[accessories] {len(catalog['accessories'])} built into {args.out} (largest penetration across poses: "
          f"{fit:.2f} mm into the part an item is fitted to, a glove's inside included; {worst:.2f} mm counting "
          "contact anywhere on the hand)")
    return 0

