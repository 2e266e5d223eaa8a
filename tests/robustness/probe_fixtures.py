"""Small real inputs for the hostile-input corpus, built once into a folder through the CLI itself: a wrist-enhanced
model of the open hand, a two-texture catalogue at 64 px, a one-ring accessory catalogue, a USD package, a .glb and a
.gltf package, and a MANO-format pickle (tests/model/mano_fixture.py).

    python tests/robustness/fixtures.py DIR        (the probe calls `build_fixtures` itself)
"""

from __future__ import annotations

import contextlib
import io
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent), str(HERE.parent / "model")]

TEXTURE_IDS = ("brown_moles_00", "light_tattoos_07")
RING = "ring_01_court_gold"
STAMP = "fixtures-ok"


def build_fixtures(fx: Path) -> Path:
    """Build (once) the fixture folder `fx`; return it."""
    from darthand.cli import main

    fx = Path(fx)
    if (fx / STAMP).is_file():
        return fx
    fx.mkdir(parents=True, exist_ok=True)
    model = str(fx / "model" / "right.npz")
    steps = [
        ["model", "build", "open", "--out-dir", str(fx / "model")],
        ["textures", "build", model, "--out", str(fx / "tex"), "--res", "64", "--ids", *TEXTURE_IDS, "--no-tx",
         "--no-sheet", "--jobs", "1"],
        ["accessories", "build", model, "--out", str(fx / "acc"), "--ids", RING, "--poses", "5", "--no-sheet"],
        ["export", "usd", model, "--out", str(fx / "usd" / "right"), "--textures", str(fx / "tex"),
         "--accessories", str(fx / "acc")],
        ["export", "gltf", model, "--out", str(fx / "glb" / "right.glb"), "--textures", str(fx / "tex")],
        ["export", "gltf", model, "--out", str(fx / "gltf" / "right.gltf"), "--textures", str(fx / "tex"),
         "--all-textures"],
    ]
    for argv in steps:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()) as err:
            code = main(argv)
        if code != 0:
            raise RuntimeError(f"fixture step {' '.join(argv)} failed: {err.getvalue()}")
    from mano_fixture import write_mano_pkl

    write_mano_pkl(fx / "MANO_RIGHT.pkl")
    (fx / STAMP).write_text("ok\n")
    return fx


if __name__ == "__main__":
    print(build_fixtures(Path(sys.argv[1])))
