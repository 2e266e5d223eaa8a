"""The `darthand render-dataset`, `darthand dataset report|export` and `darthand eval` commands: thin functions over
the dataset stage. Their options are defined in cli.py."""

from __future__ import annotations

import json
from pathlib import Path

from darthand.errors import InputError


def render_dataset(args) -> int:
    """Plan the frames of a dataset (or read them from --jobs) and render them into --out."""
    from darthand.dataset.jobs import write_jobs
    from darthand.dataset.plan import Planner, plan_spec
    from darthand.dataset.run import render_dataset as run
    from darthand.dataset.sources import SourceSpec, parse_sides, source_specs

    if args.jobs and args.plan:
        raise InputError("--plan: writes planned jobs, so it cannot be given with --jobs")
    first = SourceSpec(str(args.package), args.textures, args.accessories, args.model).open()
    jobs, origin = None, None
    if args.jobs:
        from darthand.dataset.jobs import load_jobs

        jobs, origin = load_jobs(args.jobs), {"file": str(args.jobs)}
        own = first.side
        sides = tuple(dict.fromkeys([own] + [j["side"] for j in jobs if j.get("side")]))
    else:
        sides = parse_sides(args.sides)
    specs = source_specs(args.package, sides, textures=args.textures, accessories=args.accessories,
                         model=args.model, opened=first)
    sources = {side: (first if spec.package == str(args.package) and not spec.mirror else spec.open())
               for side, spec in specs.items()}
    formats = _check_formats(args, sources)
    planner = None
    if jobs is None:
        spec = plan_spec(
            seed=args.seed, sides=list(sides),
            poses={"mode": args.pose_mode, "reference": args.poses, "gestures": _names(args.gestures),
                   "levels": args.grid_levels, "draws": args.reference_draws, "steps": args.slerp_steps,
                   "jitter_deg": args.pose_jitter, "max_reference_mb": args.max_reference_mb},
            textures=None if args.texture_ids == "all" else _names(args.texture_ids),
            skin_tone_range=args.skin_tone_range,
            skin_tone_steps=args.skin_tone_steps, accessories=_accessory_ids(args.accessory_ids),
            accessory_share=args.accessory_share, views=_names(args.views),
            shapes={"mode": getattr(args, "shapes", None), "sigma": getattr(args, "shape_sigma", None),
                    "limit": getattr(args, "shape_limit", None), "dims": getattr(args, "shape_dims", None)},
            roll_range_deg=args.roll_range, fov_range_deg=args.fov_range, margin_range=args.margin_range,
            distance_range=args.distance_range,
            lights=args.lights, backgrounds=args.backgrounds, split=args.split)
        planner = Planner(spec, sources)
        origin = {"plan": planner.spec, "start": args.start, "count": args.count}
        if args.plan:
            from darthand.dataset.run import _bounded_int

            count = _bounded_int(args.count, "count", 0, args.max_frames, "frames", "(--max-frames raises it)")
            n = write_jobs(args.plan, planner.jobs(args.start, args.start + count),
                           {"package": str(args.package), **origin})
            print(f"[render-dataset] {args.plan}: {n} jobs")
            return 0
    doc = run(args.package, args.out, jobs, planner=planner, start=args.start, count=args.count, specs=specs,
              sources=sources, processes=args.processes, threads=args.threads, size=args.size,
              samples=args.samples, aa_shading=args.aa_shading,
              shading={"ao_rays": args.ao_rays, "interreflection": args.interreflection, "skin": args.skin},
              resume=args.resume, progress=True,
              shard_size=args.shard_size, max_frames=args.max_frames, jobs_source=origin,
              cluster=None if args.ray is None else {"address": args.ray or None, "files": args.ray_files})
    t = doc["timings"]
    line = f"[render-dataset] {Path(args.out) / 'dataset.json'}: {doc['rendered']} frames rendered"
    if doc["skipped"]:
        line += f", {doc['skipped']} already there"
    if doc["rendered"] and "images_per_second" in t:
        workers = f"{t['processes']} Ray workers on {len(doc['runner']['nodes'])} nodes" \
            if doc["runner"]["kind"] == "ray" else f"{t['processes']} processes"
        line += (f", {t['images_per_second']:.1f} images/s ({t['ms_per_image']:.0f} ms per image after "
                 f"{t['startup_s']:.1f} s start-up, {workers})")
    print(line)
    skipped = doc["summary"]["skipped_backgrounds"]
    if skipped["count"]:
        print(f"[render-dataset] {skipped['count']} background images did not decode and were skipped "
              f"(listed in dataset.json): {', '.join(skipped['files'][:3])}")
    for fmt in formats:
        export_format(args.out, fmt, None, **_layout_options(args))
    return 0


def _check_formats(args, sources: dict) -> list[str]:
    """The --formats asked for, checked before anything renders: a FreiHAND layout of a hand that is not MANO is
    refused (unless --allow-non-mano) now, not after a long run."""
    from darthand.dataset import writers

    formats = _names(args.formats) or []
    for fmt in formats:
        if fmt not in writers.FORMATS:
            raise InputError(f"--formats: {fmt!r} is not one of {', '.join(writers.FORMATS)}")
    if "freihand" in formats:
        from darthand.dataset.freihand import check_mano
        check_mano({side: s.describe() for side, s in sources.items()}, "--formats freihand",
                   args.allow_non_mano)
    return formats


def _layout_options(args) -> dict:
    return {"left": args.left, "allow_non_mano": args.allow_non_mano}


def export_format(dataset, fmt: str, out, **options) -> Path:
    """Write a dataset in another layout (freihand or webdataset; options: the FreiHAND writer's left=,
    allow_non_mano=); returns where."""
    from darthand.dataset import writers

    if fmt not in writers.FORMATS:
        raise InputError(f"--format: {fmt!r} is not one of {', '.join(writers.FORMATS)}")
    where = writers.FORMATS[fmt](dataset, out, **options)
    print(f"[dataset] {fmt}: {where}")
    return where


def export(args) -> int:
    export_format(args.dataset, args.format, args.out, **_layout_options(args))
    return 0


def report(args) -> int:
    from darthand.dataset.report import write_report

    page = write_report(args.dataset, args.out, sheet=args.sheet)
    print(f"[dataset] report: {page}")
    return 0


def evaluate(args) -> int:
    from darthand.dataset.evaluate import evaluate_files, markdown_table

    result = evaluate_files(args.pred, args.gt, out=args.out)
    print(json.dumps(result, indent=2) if args.json else markdown_table(result))
    return 0


def _names(text: str | None) -> list[str] | None:
    return None if text is None else [t for t in str(text).replace(" ", ",").split(",") if t]


def _accessory_ids(text: str):
    if text == "all":
        return None
    if text == "none":
        return []
    return _names(text)
