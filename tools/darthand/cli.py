"""`darthand` command line: argument parsing only; the work is done by the stage functions.

Exit codes: 0 all is well, 1 a validation found problems, 2 a user-facing error (one line on stderr).
"""

from __future__ import annotations

import argparse
import sys

from darthand.errors import DarthandError


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "run", None):
        parser.print_help()
        return 2
    try:
        return int(args.run(args) or 0)
    except DarthandError as e:
        print(f"darthand: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("darthand: interrupted", file=sys.stderr)
        return 130


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="darthand", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(title="commands", metavar="COMMAND")
    _add_model_commands(sub)
    # -- stage command groups are added here (one function per stage, below) --
    _add_manifest_command(sub)
    return parser


def _group(sub, name: str, help: str):
    p = sub.add_parser(name, help=help, description=help)
    return p.add_subparsers(title=f"{name} commands", metavar="COMMAND")


# ---------------------------------------------------------------- model
def _add_model_commands(sub) -> None:
    from darthand.model import commands  # the stage's thin command functions

    g = _group(sub, "model", "inspect, pose and wrist-enhance MANO-layout hand models")
    model_help = "a MANO pkl, a darthand .npz, or a built-in name (open, open-left)"

    p = g.add_parser("info", help="counts, side, boundary loops, UVs of a model")
    p.add_argument("model", metavar="MODEL", help=model_help)
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    p.set_defaults(run=commands.info)

    p = g.add_parser("pose", help="pose a model with MANO pose vectors (forward pass)")
    p.add_argument("model", metavar="MODEL", help=model_help)
    p.add_argument("--pose", required=True, metavar="POSE.json", help="pose file (schemas/pose.schema.json)")
    p.add_argument("--out", required=True, metavar="OUT.npz", help="vertices (B,V,3), joints (B,16,3), keypoints (B,21,3 openpose)")
    p.add_argument("--dtype", choices=("float32", "float64"), default="float64", help="precision of the forward pass")
    p.set_defaults(run=commands.pose)

    p = g.add_parser("wrist", help="add the DART wrist (rings extruded from the wrist opening)")
    p.add_argument("model", metavar="MODEL", help=model_help)
    p.add_argument("--out", required=True, metavar="OUT.npz", help="wrist-enhanced model in darthand's format")
    p.add_argument("--rings", type=int, default=4, help="number of rings to extrude (default 4)")
    p.add_argument("--length", type=float, default=None, help="forearm extension length in metres (default: from the loop size)")
    p.add_argument("--taper", type=float, default=1.0, help="radius scale of the last ring relative to the opening (default 1.0)")
    p.add_argument("--anchor", type=int, default=None, help="vertex whose weights the new rings copy (default: 777 for MANO, else automatic)")
    p.add_argument("--smooth", action="store_true", help="blend the new rings' weights toward the root instead of copying")
    p.set_defaults(run=commands.wrist)

    p = g.add_parser("build", help="write wrist-enhanced right.npz and left.npz for the pipeline")
    p.add_argument("model", metavar="MODEL", help=model_help)
    p.add_argument("--out-dir", required=True, metavar="DIR", help="folder for right.npz and left.npz")
    p.set_defaults(run=commands.build)


# ---------------------------------------------------------------- manifest
def _add_manifest_command(sub) -> None:
    p = sub.add_parser("manifest", help="write build/manifest.json: outputs with sha256, step seconds, checks",
                       description="write build/manifest.json: outputs with sha256, step seconds, checks")
    p.add_argument("--build", default="build", help="build folder (default: build)")
    p.add_argument("--out", default=None, help="manifest path (default: BUILD/manifest.json)")

    def run(args):
        from darthand.manifest import write_manifest
        m = write_manifest(args.build, args.out)
        total = sum(e["bytes"] for e in m["outputs"])
        print(f"manifest: {len(m['outputs'])} outputs, {total / 1e6:.1f} MB, checks: {sorted(m['checks'])}")
        return 0

    p.set_defaults(run=run)


if __name__ == "__main__":
    sys.exit(main())
