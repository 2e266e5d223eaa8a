"""The `darthand template ...` commands: each takes parsed arguments, calls the stage, prints a short report.

Each handler imports lazily what only it uses, so that building the CLI (and `darthand --help`) loads none of it.
"""

from __future__ import annotations

from pathlib import Path

from darthand.errors import InputError
from darthand.template.importer import ImportParams, command_line, import_open_hand

# argparse attribute -> ImportParams field, for the options `template import` accepts.
IMPORT_OPTIONS = ("cut_distance", "hand_length", "target_vertices", "tip_tilt_deg", "nail_threshold",
                  "weight_smoothing", "uv_resolution", "uv_padding", "correctives", "corrective_train",
                  "corrective_test", "corrective_shapes", "shape_components", "shape_people",
                  "shape_calibration_people", "seed")


def import_command(args) -> int:
    """`darthand template import WHEEL [--out DIR] [options]`: write open_right.npz, PROVENANCE.json and
    LICENSE-CC0.md into DIR (default assets_src/template)."""
    params = {name: getattr(args, name) for name in IMPORT_OPTIONS if getattr(args, name, None) is not None}
    out = getattr(args, "out", None) or "assets_src/template"
    command = command_line(Path(args.wheel), Path(out), ImportParams(**params))
    fig = import_open_hand(args.wheel, out, command=command, **params)
    corr = fig["correctives"]
    corr_text = (f"correctives fitted (LBS->DQS mean {corr.get('lbs_mean_mm', float('nan')):.3f} -> "
                 f"{corr.get('corrected_mean_mm', float('nan')):.3f} mm)" if corr.get("fitted")
                 else f"correctives not fitted: {corr.get('reason')}")
    shapes = fig["shape_space"]
    explained = shapes["explained_variance"][shapes["components"] - 1] if shapes["components"] else 0.0
    shape_text = (f"{shapes['components']} shape directions ({100 * explained:.2f} "
                  f"% of the population's variance)" if shapes["components"] else "no shape space")
    print(f"{out}/open_right.npz: {fig['vertices']} vertices, {fig['faces']} faces, wrist loop "
          f"{fig['wrist_loop_vertices']}, hand length {fig['hand_length_m'] * 100:.1f} cm, regressor error "
          f"{fig['regressor']['max_error_mm']:.3f} mm; {shape_text}; {corr_text}")
    return 0


def gestures_command(args) -> int:
    """`darthand template gestures [MODEL] --out-dir DIR`: the guard of the model's gestures (fitted to it by
    `model build`, else as authored) and of its mirror image: gestures.json and the contact sheet; 1 if a check
    fails, with one line per failure naming what to change."""
    from darthand.model.load import load_model
    from darthand.template.gesture_checks import write_gesture_checks
    from darthand.template.gesture_problems import gesture_problems

    report = write_gesture_checks(load_model(args.model), args.out_dir)
    problems = gesture_problems(report, max_between_fingers=args.max_between_fingers)
    for line in problems:
        print(line)
    worst = max((r.get("between_fingers_faces", 0) for r in report.values()), default=0)
    fitted = sum(r.get("fit", {}).get("status") == "fitted" for r in report.values())
    gaps = [d for r in report.values() for d in r.get("contacts", {}).values() if d is not None]
    contact = f", contacts {min(gaps):.2f}..{max(gaps):.2f} mm apart" if gaps else ""
    print(f"{args.out_dir}/gestures.png: {len(report)} gestures ({fitted} fitted to the model), {len(problems)} "
          f"problems, at most {worst} faces where digits intersect{contact}")
    return 1 if problems else 0


def shapes_command(args) -> int:
    """`darthand template shapes [MODEL] --out-dir DIR`: shape-space checks and figures; 1 if a check fails."""
    from darthand.model.load import load_model
    from darthand.template.shape_checks import write_shape_checks

    if not 0 < args.magnitude < 100:
        raise InputError(f"--magnitude: must lie in (0, 100) standard deviations, got {args.magnitude}")
    model = load_model(args.model)
    report = write_shape_checks(model, args.out_dir, magnitude=args.magnitude,
                                max_between_fingers=args.max_between_fingers)
    for line in report["problems"]:
        print(line)
    sizes = report["hand_sizes"]
    length, breadth = sizes["hand_length_mm"]["shapes"], sizes["hand_breadth_mm"]["shapes"]
    print(f"{args.out_dir}/shapes.json: {model.num_betas} shape directions at +-{args.magnitude:g}, "
          f"{len(report['problems'])} problems; beta ~ N(0, I): hand length {length['mean']:.1f} +- {length['sd']:.1f} "
          f"mm (1-99 %: {length['p1']:.0f}-{length['p99']:.0f}), breadth {breadth['mean']:.1f} +- "
          f"{breadth['sd']:.1f} mm")
    return 1 if report["problems"] else 0
