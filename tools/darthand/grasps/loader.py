"""Reading the grasp catalogue (build/grasps/catalog.json and its grasps.npz): the scene stage's way in."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import read_json

FORMAT = "darthand-grasps"
FORMAT_VERSION = 1
ARRAYS = "grasps.npz"


@dataclass(frozen=True)
class Grasp:
    """One catalogue grasp: id '<object>/<type>/<k>', the object's id, the grasp type's name, the side ('right' or
    'left'); angles (16, 3) radians, pose (48,) MANO axis-angle on that side's model (flat hand mean), placement
    (4, 4) the object frame -> the hand's model frame (metres); per contact part its hand vertex (K,) and the
    object point (K, 3) it touches (object frame, m); figures (penetration and contact mm, iterations)."""

    id: str
    object_id: str
    type: str
    side: str
    angles: np.ndarray
    pose: np.ndarray
    placement: np.ndarray
    contact_vertices: np.ndarray
    contact_points: np.ndarray
    figures: dict
    contact_parts: tuple[str, ...] = ()


def catalog_file(path: str | Path) -> Path:
    """catalog.json of a catalogue given as the file or its folder."""
    p = Path(path)
    return p / "catalog.json" if p.is_dir() else p


def load_grasp_catalog(path, side: str | None = None, objects=None) -> list[Grasp]:
    """The catalogue's grasps (in catalogue order), only those of `side` and of the object ids `objects` if given."""
    file = catalog_file(path)
    doc = read_json(file, "grasp catalogue")
    if doc.get("format") != FORMAT or doc.get("format_version") != FORMAT_VERSION:
        raise InputError(f"{file}: not a {FORMAT} catalogue of version {FORMAT_VERSION}")
    arrays_path = file.parent / doc.get("arrays", ARRAYS)
    if not arrays_path.is_file():
        raise InputError(f"{arrays_path}: the catalogue's arrays are missing")
    wanted = None if objects is None else set(objects)
    with np.load(arrays_path) as z:
        a = {k: z[k] for k in z.files}
    out = []
    for g in doc["grasps"]:
        if (side is not None and g["side"] != side) or (wanted is not None and g["object"] not in wanted):
            continue
        i, k = g["row"], len(g["contact_parts"])
        out.append(Grasp(g["id"], g["object"], g["type"], g["side"], a["angles"][i], a["pose"][i],
                         a["placement"][i], a["contact_vertices"][i, :k].astype(np.int64),
                         a["contact_points"][i, :k], dict(g["figures"]), tuple(g["contact_parts"])))
    return out
