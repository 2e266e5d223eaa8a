"""Thin command functions for `darthand accessories ...` (arguments are defined in cli.py). Each handler imports
lazily what only it uses, so that building the CLI (and `darthand --help`) loads none of it."""

from __future__ import annotations

from darthand.accessories.build import build_accessories
from darthand.accessories.catalog import DEFAULT_SPEC, load_spec
from darthand.fileio import make_folder
from darthand.model.npz_io import load_npz


def build(args) -> int:
    """`darthand accessories build MODEL --out DIR [--spec catalog.json] [--ids ...] [--type ...]
    [--poses N] [--tolerance MM] [--no-refit] [--no-sheet] [--jobs N]`: build the catalogue on a darthand model .npz."""
    model = load_npz(args.model)
    spec = load_spec(getattr(args, "spec", None) or DEFAULT_SPEC)
    make_folder(args.out)          # before minutes of fitting, not after
    catalog = build_accessories(model, spec, args.out, ids=getattr(args, "ids", None) or None,
                                types=getattr(args, "type", None) or None,
                                n_sampled=int(getattr(args, "poses", 300)),
                                tolerance_mm=float(getattr(args, "tolerance", 1.0)),
                                refit=not getattr(args, "no_refit", False), sheet=not getattr(args, "no_sheet", False),
                                workers=int(getattr(args, "jobs", 1) or 1))
    pens = [a["max_penetration_mm"] for a in catalog["accessories"]]
    worst = max((p["poses"] or 0.0 for p in pens), default=0.0)
    fit = max(((p["fit_poses"] if "fit_poses" in p else p["poses"]) or 0.0 for p in pens), default=0.0)
    sweep = catalog["pose_sweep"]
    print(f"[accessories] {len(catalog['accessories'])} built into {args.out} (largest penetration over "
          f"{sweep['measured']} poses, {sweep.get('rejected_self_crossing', 0)} of {sweep['sampled']} samples left out "
          f"as self-crossing: {fit:.2f} mm into the part an item is fitted to, a glove's inside included; "
          f"{worst:.2f} mm counting contact anywhere on the hand)")
    return 0



def shapes(args) -> int:
    """`darthand accessories shapes MODEL --catalog CATALOG --out FILE.json [--shapes N] [--seed S]
    [--limit L] [--no-compare]`: the catalogue refitted to N sampled shapes (accessories.reshape), penetration over
    the shapes and the named gestures, with and without the refit (accessories.shape_sweep)."""
    import time

    import numpy as np

    from darthand.accessories.loader import load_accessory_catalog
    from darthand.accessories.reshape import ShapeRefitter
    from darthand.accessories.shape_sweep import penetration_over_shapes, sample_shapes, summary
    from darthand.errors import InputError
    from darthand.fileio import write_json
    from darthand.model.gestures import model_gestures

    model = load_npz(args.model)
    if model.num_betas == 0:
        raise InputError(f"{args.model}: the model has no shape directions")
    if not 1 <= args.shapes <= 10000:
        raise InputError(f"--shapes: {args.shapes} is outside 1..10000")
    accessories = load_accessory_catalog(args.catalog, side=model.side)
    gestures = model_gestures(model)           # as fitted to the built hand: what a dataset poses every shape in
    names, poses = list(gestures.names), gestures.poses
    betas = sample_shapes(model, args.shapes, args.seed, args.limit)
    t = time.perf_counter()
    refitter = ShapeRefitter(model, accessories).prepare()
    prepare = time.perf_counter() - t
    timings = [time.perf_counter()]
    for b in betas:                                   # all 50 (gloves included), as a dataset frame would
        refitter.refit(b)
        timings.append(time.perf_counter())
    all_seconds = np.diff(timings)

    def progress(n, total):
        print(f"  shape {n + 1}/{total}", flush=True)

    refit = penetration_over_shapes(model, accessories, betas, poses, refitter=refitter, progress=progress)
    out = {"model": str(args.model), "catalog": str(args.catalog), "shapes": int(len(betas)), "seed": args.seed,
           "limit": args.limit, "gestures": names, "items": len(refit["ids"]), "accessories": len(accessories),
           "betas": np.round(betas, 4).tolist(),
           "refit_seconds": {"prepare": round(prepare, 3), "all_items_mean": round(float(all_seconds.mean()), 4),
                             "all_items_max": round(float(all_seconds.max()), 4)},
           "refit": summary(refit, names)}
    if not args.no_compare:
        out["without_refit"] = summary(penetration_over_shapes(model, accessories, betas, poses, refit=False,
                                                               refitter=refitter), names)
    write_json(args.out, out)
    r = out["refit"]
    line = (f"{args.out}: {len(accessories)} accessories refitted to {len(betas)} shapes in "
            f"{out['refit_seconds']['all_items_mean'] * 1000:.0f} ms each (after {prepare:.1f} s once); rigid items "
            f"over the shapes x {len(names)} gestures: fit penetration max {r['fit_max_mm']:.2f} mm, "
            f"p99 {r['fit_p99_mm']:.2f} mm")
    if "without_refit" in out:
        line += f" (without refitting: max {out['without_refit']['fit_max_mm']:.2f} mm)"
    print(line)
    return 0
