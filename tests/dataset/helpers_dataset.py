"""Helpers of the dataset stage's tests (conftest.py has the fixtures)."""

from __future__ import annotations

SIZE = 48          # pixels: the frames only have to be real renders, not pretty ones
TEXTURES = ("light_moles_00", "dark_moles_01")


def render(planner, sources, out, count, **kw):
    from darthand.dataset.run import render_dataset

    opened, specs = sources
    kw.setdefault("processes", 1)
    return render_dataset(specs["right"].package, out, planner=planner, count=count, specs=specs, sources=opened,
                          size=SIZE, samples=4, progress=False, **kw)


def files_of(folder) -> dict:
    """{relative path: bytes} of a dataset's frame files (dataset.json holds timings, so it differs)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != "dataset.json"}
