"""`darthand validate PATH... [--json] [--render] [--deep] [--out REPORT.json]`: the thin command over
`run.validate_paths`. Exit code 0 clean, 1 problems found, 2 a file could not be read (or --render without the
renderer). Its options are defined in cli.py. Each handler imports lazily
what only it uses, so that building the CLI (and `darthand --help`) loads none of it."""

from __future__ import annotations

from darthand.fileio import write_json

HELP = "check USD (.usda/.usdc/.usdz) and glTF (.glb/.gltf) hand packages; exit 0 clean, 1 problems, 2 unreadable"


def validate(args) -> int:
    from darthand.validate.report import render_json, render_text
    from darthand.validate.run import validate_paths

    report = validate_paths(args.paths, render=args.render, deep=args.deep)
    print(render_json(report) if args.json else render_text(report))
    if args.out:
        write_json(args.out, report.as_dict())
    return report.exit_code
