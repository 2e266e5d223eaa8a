"""Thin command functions for `darthand grasps ...` (arguments are defined in cli.py). The object catalogue's loader
is imported when a command runs (the objects stage, below this one)."""

from __future__ import annotations

import importlib

from darthand.errors import InputError
from darthand.fileio import make_folder
from darthand.grasps.build import build_grasps


def build(args) -> int:
    """`darthand grasps build RIGHT.npz LEFT.npz --objects CATALOG --out DIR [--ids ...] [--jobs N]
    [--no-sheet]`: fit every catalogue object's grasps on both models."""
    items = object_loader().load_object_catalog(args.objects, ids=args.ids or None)
    if not items:
        raise InputError(f"{args.objects}: no objects to grasp")
    make_folder(args.out)
    timing: dict = {}
    doc = build_grasps(items, {"right": args.right, "left": args.left}, args.out, jobs=max(1, args.jobs),
                       sheet=not args.no_sheet, timing=timing)
    c, f = doc["counts"], doc["figures"]
    print(f"[grasps] {c['fitted']} grasps of {c['objects']} objects into {args.out} ({c['dropped']} dropped; "
          f"penetration max {f['penetration_max_mm']:.2f} mm, contacts within {f['contact_max_mm']:.2f} mm; "
          f"{timing['build_s']:.0f} s)")
    return 0


def object_loader():
    """The objects stage's loader module (imported when a command runs; refused in one line where that stage is
    not installed)."""
    try:
        return importlib.import_module("darthand.objects.loader")
    except ModuleNotFoundError:
        raise InputError("darthand.objects: the object catalogue stage is not installed (grasps need its "
                         "loader)") from None
