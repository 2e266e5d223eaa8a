"""The `darthand render` and `render-checks` commands: thin functions over render.api and render.checks
(`render-dataset` is the dataset stage's: dataset/commands.py).

Their options are defined in cli.py. The handlers import the renderer lazily, when they run (embreex, OpenImageIO
and the compiled kernels: about a second), so `darthand --help` does not load it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import read_json
from darthand.render.scenes import HandBody, Scene


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


def environment_lights(args):
    """The lights of `render`: --lights (a path or None) as given without --environment; with it, a lights document
    whose "environment" field is --environment, --environment-rotation and --environment-strength (and whose
    ambient and lights are --lights', or none)."""
    if args.environment is None:
        return args.lights
    doc = dict(read_json(Path(args.lights), "lights file")) if args.lights else {}
    doc["environment"] = {"map": args.environment, "rotation": args.environment_rotation,
                          "strength": args.environment_strength}
    return doc


def render(args) -> int:
    """Render one labelled image of PACKAGE into --out."""
    from darthand.render.api import Renderer, open_source, write_frame
    from darthand.render.film import load_film

    source = open_source(args.package, textures=args.textures, accessories=args.accessories, model=args.model)
    pose = parse_pose(args.pose)
    if isinstance(pose, int) and source.pose_model() is not None:
        raise InputError("--pose: a time code needs a USD package; give a gesture name or a pose vector")
    is_file = isinstance(pose, str) and Path(pose).is_file()
    hand = HandBody(pose=tuple(pose) if isinstance(pose, np.ndarray) else pose,
                    pose_index=args.pose_index if is_file and args.pose_index else None, texture=args.texture,
                    skin_tone_offset=args.skin_tone_offset, accessory=args.accessory)
    scene = Scene((hand,), args.camera, environment_lights(args), args.background)
    width, height = args.width or args.size, args.height or args.size
    renderer = Renderer(source, args.threads)
    if args.engine == "cycles":
        from darthand.render.cycles import CyclesRenderer, check_available  # lazy, as the renderer above

        check_available()
        renderer = CyclesRenderer(renderer, args.cycles_samples)
    frame = renderer.render_scene(
        scene, width=width, height=height, samples=args.samples, aa_shading=args.aa_shading,
        keypoint_order=args.keypoint_order,
        shading={"ao_rays": args.ao_rays, "interreflection": args.interreflection, "skin": args.skin,
                 "skin_specular": args.skin_specular, "skin_detail": args.skin_detail,
                 "shadows": args.shadows},
        film=load_film(args.film, args.film_seed), film_seed=args.film_seed, subdivision=args.subdivision,
        arm=args.arm)
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
        verdict = "all checks pass" if not failed else "FAILED: " + ", ".join(failed)
        print(f"[render] {side}: {pkg['renders']} renders, {verdict}"
              f" ({pkg['seconds']:.1f} s)")
    print(f"[render] {Path(report['report'])}: {'ok' if report['ok'] else 'problems found'}")
    return 0 if report["ok"] else 1
