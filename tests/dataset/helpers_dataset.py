"""Helpers of the dataset stage's tests (conftest.py has the fixtures)."""

from __future__ import annotations

SIZE = 48          # pixels: the frames only have to be real renders, not pretty ones
TEXTURES = ("light_moles_00", "dark_moles_01")


def render(planner, sources, out, count, **kw):
    """Frames 0 .. count - 1 of `planner` rendered into `out` at SIZE (kw: more DatasetOptions fields)."""
    from darthand.dataset.options import DatasetOptions
    from darthand.dataset.run import render_frames

    opened, specs = sources
    kw.setdefault("processes", 1)
    options = DatasetOptions(specs["right"].package, str(out), count=count, size=SIZE, samples=4, progress=False,
                             **kw)
    return render_frames(options, opened, specs, planner)


def files_of(folder) -> dict:
    """{relative path: bytes} of a dataset's frame files (dataset.json holds timings, so it differs)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != "dataset.json"}


class BakedPackage:
    """What a plan asks of a USD package (render/source.FrameSource without OpenUSD): baked gestures, ids."""

    kind, source, side, worn_rings = "usd", "stub.usda", "right", False

    def __init__(self, gestures=("flat", "fist"), textures=("light_a_00",), accessories=("none", "watch_01")):
        self.gestures, self.textures, self.accessories = list(gestures), list(textures), list(accessories)

    def pose_model(self):
        return None

    def gesture_names(self):
        return list(self.gestures)

    def texture_ids(self):
        return list(self.textures)

    def accessory_ids(self):
        return list(self.accessories)

    def accessory_type(self, accessory_id):
        return None

    def describe(self):
        return {"source": "usd", "format": "usd"}

    def relabel(self, name):
        self.source = name

    def subject(self, pose=None, **options):
        raise NotImplementedError("a plan never poses its sources")
