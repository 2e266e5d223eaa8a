"""The `darthand render-dataset`, `darthand dataset report|export` and `darthand eval` commands: thin functions over
the dataset stage (render-dataset: dataset/api.py). Their options are defined in cli.py. The handlers import the
stage's modules lazily, when they run, so each command starts with only what it uses."""

from __future__ import annotations

import json
from pathlib import Path

from darthand.dataset.options import ClusterOptions, DatasetOptions
from darthand.dataset.plan import PlanOptions, PoseOptions, ShapeOptions
from darthand.dataset.sources import parse_sides
from darthand.errors import InputError


def render_dataset(args) -> int:
    """Plan the frames of a dataset (or read them from --jobs) and render them into --out; with --plan, write the
    planned jobs instead."""
    from darthand.dataset.api import render_dataset as render
    from darthand.dataset.api import write_plan

    options = dataset_options(args)
    if args.plan:
        if args.jobs:
            raise InputError("--plan: writes planned jobs, so it cannot be given with --jobs")
        print(f"[render-dataset] {args.plan}: {write_plan(options, args.plan)} jobs")
        return 0
    doc = render(options)
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
    return 0


def dataset_options(args) -> DatasetOptions:
    """The run's options from render-dataset's arguments (cli.py defines them, with these classes' defaults)."""
    poses = PoseOptions(mode=args.pose_mode, reference=args.poses, gestures=_names(args.gestures),
                        levels=args.grid_levels, draws=args.reference_draws, steps=args.slerp_steps,
                        jitter_deg=args.pose_jitter, max_reference_mb=args.max_reference_mb)
    shapes = ShapeOptions(mode=args.shapes, sigma=args.shape_sigma, limit=args.shape_limit, dims=args.shape_dims)
    plan = PlanOptions(
        seed=args.seed, sides=parse_sides(args.sides), poses=poses, shapes=shapes,
        textures=None if args.texture_ids == "all" else _names(args.texture_ids),
        skin_tone_range=args.skin_tone_range, skin_tone_steps=args.skin_tone_steps,
        accessories=_accessory_ids(args.accessory_ids), accessory_share=args.accessory_share,
        views=tuple(_names(args.views) or ()), roll_range_deg=args.roll_range, fov_range_deg=args.fov_range,
        margin_range=args.margin_range, distance_range=args.distance_range, lights=args.lights,
        environments=args.environments, backgrounds=args.backgrounds, split=args.split,
        two_hands=args.two_hands, interactions=args.interactions,
        interaction_fit=args.interaction_fit, objects=args.objects,
        object_categories=_names(args.object_categories))
    return DatasetOptions(
        str(args.package), args.out, count=args.count, start=args.start, jobs=args.jobs, plan=plan,
        textures=args.textures, accessories=args.accessories, model=args.model,
        objects_catalog=args.objects_catalog, grasps_catalog=args.grasps_catalog, size=args.size,
        samples=args.samples, aa_shading=args.aa_shading,
        shading={"ao_rays": args.ao_rays, "interreflection": args.interreflection, "skin": args.skin,
                 "skin_specular": args.skin_specular, "skin_detail": args.skin_detail,
                 "shadows": args.shadows},
        engine=args.engine, cycles_samples=args.cycles_samples, film=args.film, processes=args.processes,
        threads=args.threads,
        geometry={"subdivision": args.subdivision, "arm": args.arm},
        cluster=None if args.ray is None else ClusterOptions(args.ray or None, args.ray_files),
        resume=args.resume, shard_size=args.shard_size, max_frames=args.max_frames,
        maps=tuple(_names(args.maps) or ()), formats=tuple(_names(args.formats) or ()), left=args.left,
        allow_non_mano=args.allow_non_mano)


def export(args) -> int:
    from darthand.dataset.api import export_format

    export_format(args.dataset, args.format, args.out, left=args.left, allow_non_mano=args.allow_non_mano)
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
