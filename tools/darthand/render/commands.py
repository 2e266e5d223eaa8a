"""The `darthand render`, `render-checks` and `render-dataset` commands: thin functions over render.api,
render.checks and render.dataset.

Their options are defined in cli.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darthand.errors import InputError


def parse_pose(text: str | None):
    """--pose: None, a gesture name or pose file path (strings), 48 comma-separated numbers, or an int time code."""
    if text is None:
        return None
    parts = [p for p in text.replace(" ", ",").split(",") if p]
    if len(parts) > 1:
        try:
            return np.array([float(p) for p in parts])
        except ValueError:
            raise InputError(f"--pose: {text[:40]!r} is not 48 comma-separated numbers") from None
    if text.isdigit():
        return int(text)
    return text


def render(args) -> int:
    """Render one labelled image of PACKAGE into --out."""
    from darthand.render.api import Renderer, open_source, write_frame

    source = open_source(args.package, textures=args.textures, accessories=args.accessories, model=args.model)
    pose = parse_pose(args.pose)
    if isinstance(pose, str) and Path(pose).is_file() and args.pose_index and hasattr(source, "model"):
        from darthand.render.poses import resolve_pose

        pose = resolve_pose(source.model, pose, args.pose_index)[0]
    if isinstance(pose, int) and not hasattr(source, "gestures"):
        raise InputError("--pose: a time code needs a USD package; give a gesture name or a pose vector")
    width, height = args.width or args.size, args.height or args.size
    renderer = Renderer(source, args.threads)
    frame = renderer.render(pose, texture=args.texture, skin_tone_offset=args.skin_tone_offset,
                            accessory=args.accessory, camera=args.camera, lights=args.lights,
                            background=args.background, width=width, height=height, samples=args.samples,
                            aa_shading=args.aa_shading, keypoint_order=args.keypoint_order,
                            shading={"ao_rays": args.ao_rays, "interreflection": args.interreflection,
                                     "skin": args.skin})
    paths = write_frame(frame, args.out, depth=args.depth)
    lab = frame.labels
    total = sum(frame.timings.values())
    print(f"{paths['image']}: {width}x{height}, {lab['side']} hand, texture {lab['texture']['id']}, accessory "
          f"{lab['accessory']['id']}, coverage {lab['coverage']:.1%}, {sum(lab['visibility'])}/21 keypoints "
          f"visible, {1000 * total:.0f} ms")
    return 0


def checks(args) -> int:
    """Render every package of a build, check the renders, write BUILD/checks/*.png and report.json; exit 1 when
    a check fails."""
    from darthand.render.checks import run_checks

    report = run_checks(args.build, args.out, sides=args.sides, size=args.size,
                        all_accessories=args.all_accessories)
    for side, pkg in report["packages"].items():
        failed = [name for name, c in pkg["checks"].items() if not c["ok"]]
        print(f"[render] {side}: {pkg['renders']} renders, {'all checks pass' if not failed else 'FAILED: ' + ', '.join(failed)}"
              f" ({pkg['seconds']:.1f} s)")
    print(f"[render] {Path(report['report'])}: {'ok' if report['ok'] else 'problems found'}")
    return 0 if report["ok"] else 1


def dataset(args) -> int:
    """Plan the frames of a dataset (or read them from --jobs) and render them into --out with worker processes."""
    from darthand.render.api import open_source
    from darthand.render.dataset import plan_frames, render_dataset, write_jobs

    source = open_source(args.package, textures=args.textures, accessories=args.accessories, model=args.model)
    origin = None
    jobs = args.jobs
    if args.jobs and args.plan:
        raise InputError("--plan: writes planned jobs, so it cannot be given with --jobs")
    if not args.jobs:
        origin = {"seed": args.seed, "start": args.start, "count": args.count, "gestures": args.gestures,
                  "poses": args.poses, "pose_jitter_deg": args.pose_jitter, "texture_ids": args.texture_ids,
                  "skin_tone_range": _pair("--skin-tone-range", args.skin_tone_range),
                  "skin_tone_steps": args.skin_tone_steps, "accessory_ids": args.accessory_ids,
                  "no_accessory_share": args.no_accessory_share, "views": _names(args.views),
                  "roll_range_deg": _pair("--roll-range", args.roll_range), "lights": args.lights}
        jobs = plan_frames(source, args.count, seed=args.seed, start=args.start, poses=_poses(source, args),
                           textures=None if args.texture_ids == "all" else _names(args.texture_ids),
                           accessories=_accessory_ids(args.accessory_ids), views=origin["views"],
                           skin_tone_range=origin["skin_tone_range"], skin_tone_steps=args.skin_tone_steps,
                           no_accessory_share=args.no_accessory_share, pose_jitter_deg=args.pose_jitter,
                           roll_range_deg=origin["roll_range_deg"], lights=args.lights)
        if args.plan:
            write_jobs(args.plan, jobs, {"package": str(args.package), **origin})
            print(f"[render-dataset] {args.plan}: {len(jobs)} jobs")
            return 0
    doc = render_dataset(args.package, args.out, jobs, processes=args.processes, size=args.size,
                         samples=args.samples, aa_shading=args.aa_shading, background=args.background,
                         textures=args.textures, accessories=args.accessories, model=args.model, resume=args.resume,
                         progress=True, source=source, jobs_source=origin)
    t = doc["timings"]
    line = f"[render-dataset] {Path(args.out) / 'dataset.json'}: {doc['rendered']} frames rendered"
    if doc["skipped"]:
        line += f", {doc['skipped']} already there"
    if doc["rendered"]:
        line += (f", {t['images_per_second']:.1f} images/s ({t['ms_per_image']:.0f} ms per image after "
                 f"{t['startup_s']:.1f} s start-up, {t['processes']} processes)")
    print(line)
    return 0


def _names(text: str | None) -> list[str] | None:
    return None if text is None else [t for t in text.replace(" ", ",").split(",") if t]


def _pair(option: str, text: str) -> tuple[float, float]:
    parts = _names(text)
    try:
        lo, hi = (float(p) for p in parts)
    except ValueError:
        raise InputError(f"{option}: {text!r} is not two comma-separated numbers LO,HI") from None
    return lo, hi


def _poses(source, args) -> list[str] | None:
    """--gestures and --poses as plan_frames' `poses` (None: every gesture)."""
    files = [args.poses] if args.poses else []
    if args.gestures in (None, "all"):
        if not files:
            return None
        if args.gestures is None:
            return files
        from darthand.model.poses import list_gestures

        return (list_gestures() if hasattr(source, "model") else list(source.gestures)) + files
    return _names(args.gestures) + files


def _accessory_ids(text: str):
    if text == "all":
        return None
    if text == "none":
        return []
    return _names(text)
