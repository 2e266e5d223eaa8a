"""Contact sheets of the grasp catalogue: per object category, a few grasps each, the hand closed on its object
(accessories/preview's Embree view framed on the object, two views per grasp: at the palm, at the thumb), and an
overview (`overview_sheet`: a row per category, several objects and types each, the palm's view)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darthand.accessories.preview import render_view
from darthand.grasps.build import APPROACHES
from darthand.model.forward import forward
from darthand.model.npz_io import load_npz
from darthand.model.preview import contact_sheet, write_png

OBJECT_COLOR = np.array([0.15, 0.35, 0.7])   # linear
PER_CATEGORY = 12                            # grasps drawn per category sheet
PER_ROW = 6                                  # grasps per category in the overview
TILE = 200
VIEWS = ((0.3, 1.0, -0.5), (0.2, 0.3, -1.0))   # ray directions, hand model frame: at the palm, at the thumb's side


def grasp_images(model, item, fit, tile: int = TILE) -> list[np.ndarray]:
    """The views of one grasp (a GraspFit or Grasp: pose (48,), placement (4, 4)), hand model frame."""
    v = np.asarray(forward(model, np.asarray(fit.pose)[None]).vertices[0], np.float64)
    P = np.asarray(fit.placement)
    obj = np.asarray(item.vertices) @ P[:3, :3].T + P[:3, 3]
    meshes = [{"vertices": v, "faces": model.faces}, {"vertices": obj, "faces": item.faces, "color": OBJECT_COLOR}]
    centre = 0.5 * (obj.min(0) + obj.max(0))
    extent = max(float(np.ptp(obj, axis=0).max()) * 1.3, 0.14)
    return [render_view(meshes, centre, view, (-1.0, 0.0, 0.0), extent, tile) for view in VIEWS]


def contact_sheets(items, fitted: list[dict], model_paths: dict, out: Path) -> dict:
    """Write grasps_<category>.png per category (up to PER_CATEGORY right-hand grasps, a few per object, and one
    left one) into `out`; returns {category: file name}."""
    models = {s: load_npz(p) for s, p in model_paths.items()}
    by_id = {it.id: it for it in items}
    sheets = {}
    for category in sorted({it.category for it in items}):
        chosen = pick(fitted, {i for i, it in by_id.items() if it.category == category})
        images, labels = [], []
        for r in chosen:
            for k, im in enumerate(grasp_images(models[r["side"]], by_id[r["object"]], r["fit"])):
                images.append(im)
                labels.append(f"{r['id']} {r['side'][0]}"[:34] if k == 0 else "")
        if images:
            name = f"grasps_{category}.png"
            write_png(out / name, contact_sheet(images, labels, cols=6))
            sheets[category] = name
    return sheets


def pick(fitted: list[dict], object_ids: set) -> list[dict]:
    """Up to PER_CATEGORY grasps of these objects: round-robin over objects and types, the right hand's, plus the
    first left one."""
    rows = [r for r in fitted if r["object"] in object_ids]
    right = [r for r in rows if r["side"] == "right"]
    seen: set = set()
    first: list[dict] = []
    rest: list[dict] = []
    for r in right:
        key = (r["object"], r["type"], r["approach"] >= APPROACHES)     # a handle grasp apart from the body's
        (rest if key in seen else first).append(r)
        seen.add(key)
    left = [r for r in rows if r["side"] == "left"][:1]
    return (first + rest)[:PER_CATEGORY - len(left)] + left


def overview_sheet(items, fitted: list[dict], model_paths: dict, path: Path, per_row: int = PER_ROW) -> None:
    """Write one PNG at `path`: a row per category, its first `per_row` grasps by `pick` (distinct objects and
    types first), each seen at the palm."""
    models = {s: load_npz(p) for s, p in model_paths.items()}
    by_id = {it.id: it for it in items}
    images, labels = [], []
    for category in sorted({it.category for it in items}):
        chosen = [r for r in pick(fitted, {i for i, it in by_id.items() if it.category == category})
                  if r["side"] == "right"][:per_row]
        for r in chosen:
            images.append(grasp_images(models[r["side"]], by_id[r["object"]], r["fit"])[0])
            labels.append(f"{r['id']}"[:30])
        blank = np.full((TILE, TILE, 3), 0.2, np.float32)
        images += [blank] * (per_row - len(chosen))
        labels += [""] * (per_row - len(chosen))
    write_png(path, contact_sheet(images, labels, cols=per_row))
