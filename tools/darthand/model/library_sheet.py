"""The pose library's contact sheet: every pose drawn on a model (model/preview), group by group, each labelled
with its name and first tags, so a person can check the poses look like what they are named."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darthand.model.forward import forward
from darthand.model.hand_model import HandModel
from darthand.model.library_fit import ModelLibrary
from darthand.model.preview import contact_sheet, render_mesh, write_png

# Fingers up, seen from the palm, a little from the wrist: how a signer's right hand faces the person reading it.
SHEET_VIEW = (0.0, -1.0, 0.15)


def library_sheets(model: HandModel, library: ModelLibrary, out_dir: str | Path, size: int = 200,
                   cols: int = 7, view=SHEET_VIEW) -> list[Path]:
    """Write <out_dir>/library_<group>.png per group (poses in library order); returns the paths."""
    out_dir = Path(out_dir)
    paths = []
    for group in dict.fromkeys(library.groups):
        keep = [k for k, g in enumerate(library.groups) if g == group]
        images = [pose_image(model, library.poses[k], size, view) for k in keep]
        labels = [label(library.names[k], library.tags[k], group) for k in keep]
        path = out_dir / f"library_{group}.png"
        write_png(path, contact_sheet(images, labels, cols=min(cols, len(images)), label_height=22))
        paths.append(path)
    return paths


def pose_image(model: HandModel, pose: np.ndarray, size: int, view) -> np.ndarray:
    """(size, size, 3) preview of the model in one (48,) pose."""
    v = forward(model, np.asarray(pose, np.float64)[None]).vertices[0]
    return render_mesh(v, model.faces, view=np.asarray(view, np.float64), size=size, side=model.side)


def label(name: str, tags: tuple[str, ...], group: str) -> str:
    """The pose's name and its first tag that are not its group's."""
    extra = [t for t in tags if t not in (group, "asl", "gesture", "rest", "grip", "counting", "empty_handed")
             and not t.startswith(("letter_", "number_"))]
    return f"{name} {extra[0]}" if extra else name
