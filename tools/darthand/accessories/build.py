"""The accessories stage: fit, generate, verify across poses and write the catalogue.

Per accessory `build/accessories/<id>.*`:
  <id>.npz    geometry container (format "darthand-accessory", version 1), float64/int64, no pickles:
              vertices (N, 3)   rest-pose positions in the model's frame, metres
              local_vertices (N, 3) the same in the accessory's local frame (rigid items; = vertices for gloves)
              faces (F, 3)      outward, counter-clockwise
              normals (N, 3)    area-weighted vertex normals (model frame)
              uvs (T, 2), faces_uv (F, 3)  per-corner texture coordinates (OpenGL convention, v up)
              parent_joint ()   MANO joint index, -1 for gloves
              rest_transform (4, 4)  local frame -> model rest frame (identity for gloves); posed = G_j @ rest
              weights (N, 16), posedirs (N, 3, 135), shapedirs (N, 3, S), source_vertex (N,), layer (N,)  gloves only
              id, type, material_json
  <id>.obj + <id>.mtl   rest-pose mesh with UVs and normals, material referencing the textures
  <id>_basecolor.png    sRGB albedo;  <id>_metallic_roughness.png  raw, glTF layout (G roughness, B metallic)
and catalog.json (schemas/accessory_catalog.schema.json) and contact_sheet.png.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from darthand.accessories import catalog as cat
from darthand.accessories.item import Built, generate
from darthand.accessories.preview import render_view
from darthand.accessories.placement import TRAINING_POSES, place_rings
from darthand.accessories.sweep import measure, sweep_poses
from darthand.accessories.textures import linear_to_srgb
from darthand.errors import InputError
from darthand.fileio import atomic_path, write_bytes, write_json
from darthand.model.hand_model import HandModel
from darthand.model.layout import JOINT_NAMES
from darthand.model.preview import contact_sheet, write_png
from darthand.model.topology import vertex_normals

FORMAT, FORMAT_VERSION = "darthand-accessory", 1


# ---------------------------------------------------------------- the stage
def build_accessories(model: HandModel, spec: dict, out_dir: str | Path, ids=None, types=None, *,
                      n_sampled: int = 300, gestures: list[str] | None = None, tolerance_mm: float = 1.0,
                      refit: bool = True, sheet: bool = True, tile: int = 192, workers: int = 1,
                      placement_poses: int = TRAINING_POSES) -> dict:
    """Build the catalogue's accessories (or the `ids` / `types` subset) on `model` into `out_dir`; return and
    write catalog.json. Rings are placed and their bores sized over training poses (`placement`, with `refit`);
    rigid items whose fit penetration across the sweep still exceeds `tolerance_mm` are refitted once with their
    clearance grown by the excess (both figures are reported). `workers` processes share the pose sweeps;
    `placement_poses` sampled poses (with the rest pose and `gestures`) train the ring placement."""
    if model.side != "right":
        raise InputError(f"{model.meta.get('source', 'model')}: accessories are fitted on a right hand "
                         f"(got side {model.side!r}); mirror the built accessories for the left")
    out_dir = Path(out_dir)
    seed = int(spec["seed"])
    items = cat.entries(spec, ids, types)
    placed = place_rings(model, items, seed, workers, placement_poses, gestures) if refit else {}
    built = []
    for e in items:
        p = placed.get(e["id"])
        b = generate(model, e, seed) if p is None else generate(model, {**e, "t": p.t}, seed, clearance=p.clearance)
        b.figures = {"before_refit": None, "placement": p}
        built.append(b)
    names, poses = sweep_poses(model, seed, n_sampled, gestures)
    figures = measure(model, built, poses, workers)
    tol = tolerance_mm / 1000.0
    n_named = sum(not n.startswith("sample_") for n in names)      # rest and gestures
    n_kept = len(names) - n_named
    regrown = []
    for i, b in enumerate(built):
        worst = float(figures[b.id]["fit"][1:].max(initial=0.0))
        if refit and b.fit is not None and worst > tol:    # what a larger bore fixes; growth capped at 2 mm
            grown = generate(model, b.entry, seed, clearance=b.clearance + min(worst - tol / 2, 0.002))
            grown.figures = {**b.figures, "before_refit": worst * 1000.0}
            built[i] = grown
            regrown.append(grown)
    if regrown:
        figures.update(measure(model, regrown, poses, workers))
    out_dir.mkdir(parents=True, exist_ok=True)
    entries_out = [write_accessory(out_dir, b, figures[b.id], names, n_named) for b in built]
    sheet_name = None
    if sheet and built:
        sheet_name = "contact_sheet.png"
        write_contact_sheet(model, built, out_dir / sheet_name, tile)
    catalog = {"format": "darthand-accessory-catalog", "format_version": 1, "seed": seed,
               "model": {"source": str(model.meta.get("source", "model")), "side": model.side},
               "pose_sweep": {"gestures": names[1:n_named], "sampled": int(n_sampled),
                              "rejected_self_crossing": int(n_sampled - n_kept), "measured": len(names),
                              "tolerance_mm": tolerance_mm, "table_mm": penetration_table(entries_out)},
               "contact_sheet": sheet_name, "accessories": entries_out}
    cat.check_catalog(catalog, str(out_dir / "catalog.json"))
    write_json(out_dir / "catalog.json", catalog)
    return catalog


# The penetration table's columns (catalogue fields, mm): rigid items into the part they are fitted to and contact
# anywhere on the hand; gloves into their inner surface and through their outer one.
TABLE_COLUMNS = {"rigid": {"fit": "fit_poses", "contact": "poses"},
                 "glove": {"fit": "poses", "through": "through_poses"}}


def penetration_table(entries: list[dict]) -> dict:
    """Per accessory type, over the sweep's poses (mm): each column's largest value and its item, and the worst
    item's 99th percentile over the poses and that item; for rings, `worn`: how they were worn (`worn_summary`)
    summed over the items -- poses turned, the largest turn (degrees), the slide range (mm)."""
    table = {}
    for kind in sorted({e["type"] for e in entries}):
        pens = {e["id"]: e["max_penetration_mm"] for e in entries if e["type"] == kind}
        row: dict = {"items": len(pens)}
        for column, field in TABLE_COLUMNS["glove" if kind == "glove" else "rigid"].items():
            worst = {i: p[field] for i, p in pens.items() if p.get(field) is not None}
            p99 = {i: p[field + "_p99"] for i, p in pens.items() if p.get(field + "_p99") is not None}
            if worst and p99:
                top, top99 = max(worst, key=worst.__getitem__), max(p99, key=p99.__getitem__)
                row[column] = {"max": round(worst[top], 4), "item": top, "worst_p99": round(p99[top99], 4),
                               "worst_p99_item": top99}
        worn = [e["worn"] for e in entries if e["type"] == kind and "worn" in e]
        if worn:
            row["worn"] = {"poses": sum(w["poses_turned"] for w in worn),
                           "turned_max_deg": max(w["turned_max_deg"] for w in worn),
                           "slide_mm": [min(w["slide_mm"][0] for w in worn), max(w["slide_mm"][1] for w in worn)]}
        table[kind] = row
    return table


def write_accessory(out_dir: Path, b: Built, fig: dict, pose_names: list[str], n_named: int) -> dict:
    """Write one accessory's files; return its catalogue entry. Penetrations (mm): `rest`; `gestures` (the named
    gestures); `poses` (gestures and sampled poses) with the worst pose's name; for rigid items `fit_*` counts
    only the hand part the item is fitted to (neighbouring fingers excluded); for gloves `through_*` is the depth
    beyond the outer surface (the plain figures: beyond the inner surface)."""
    m = b.mesh
    files = {"npz": f"{b.id}.npz", "obj": f"{b.id}.obj", "mtl": f"{b.id}.mtl",
             "base_color": f"{b.id}_basecolor.png", "metallic_roughness": f"{b.id}_metallic_roughness.png"}
    material = {k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in m.material.items()}
    material.update(base_color_texture=files["base_color"], metallic_roughness_texture=files["metallic_roughness"])
    world = b.world_vertices
    normals = vertex_normals(world, m.faces)
    _write_npz(out_dir / files["npz"], b, world, normals, material)
    write_bytes(out_dir / files["obj"], _obj_text(b.id, world, normals, m.uvs, m.faces, m.faces_uv).encode())
    write_bytes(out_dir / files["mtl"], _mtl_text(b.id, material, files).encode())
    write_image(out_dir / files["base_color"], m.textures["base_color"], srgb=True)
    write_image(out_dir / files["metallic_roughness"], m.textures["metallic_roughness"], srgb=False)
    depth_mm = fig["depth"] * 1000.0
    sweep = depth_mm[1:]
    pen = {"rest": float(depth_mm[0]), "poses": float(sweep.max()) if len(sweep) else None,
           "poses_p99": float(np.percentile(sweep, 99)) if len(sweep) else None,
           "gestures": float(depth_mm[1:n_named].max()) if n_named > 1 else None,
           "worst_pose": pose_names[1 + int(np.argmax(sweep))] if len(sweep) and sweep.max() > 0 else None,
           "before_refit": b.figures.get("before_refit")}
    if b.fit is not None:
        fit_mm = fig["fit"] * 1000.0
        pen.update(fit_rest=float(fit_mm[0]), fit_poses=float(fit_mm[1:].max()) if len(sweep) else None,
                   fit_poses_p99=float(np.percentile(fit_mm[1:], 99)) if len(sweep) else None,
                   fit_gestures=float(fit_mm[1:n_named].max()) if n_named > 1 else None)
    else:
        through = fig["through"] * 1000.0
        pen.update(through_rest=float(through[0]), through_poses=float(through[1:].max()) if len(sweep) else None,
                   through_poses_p99=float(np.percentile(through[1:], 99)) if len(sweep) else None,
                   through_gestures=float(through[1:n_named].max()) if n_named > 1 else None)
    joint = None if b.fit is None else int(b.fit.joint)
    entry = {"id": b.id, "type": b.entry["type"], "style": _style(b.entry), "parent_joint": joint,
             "parent_joint_name": None if joint is None else JOINT_NAMES[joint],
             "fitted_size": {k + "_mm": round(float(v) * 1000.0, 4) for k, v in m.dims.items()
                             if not k.startswith("ring_size") and k != "covered_faces"},
             "clearance_mm": round(b.clearance * 1000.0, 4),
             "max_penetration_mm": pen, "material": material, "files": files,
             "vertices": int(len(m.vertices)), "triangles": int(len(m.faces)), "parts": int(m.part_count)}
    for k in ("ring_size_eu", "ring_size_us"):
        if k in m.dims:
            entry["fitted_size"][k] = round(float(m.dims[k]), 3)
    if b.fit is not None:
        entry["rest_transform"] = b.fit.rest.tolist()
        entry["axis_distance_mm"] = round(b.fit.axis_distance * 1000.0, 4)
        entry["max_axis_drift_mm"] = float(fig["drift"] * 1000.0) if len(sweep) else None
        if b.entry["type"] == "ring":
            entry["worn"] = worn_summary(fig, n_named)
            entry["finger"] = b.entry["finger"]
            entry["position_along_bone"] = float(b.entry.get("t", 0.5))
            p = b.figures.get("placement")
            if p is not None:
                entry["placement_worst_fit_mm"] = {f"{t:g}": round(w * 1000.0, 4) for t, w in
                                                   p.worst_by_position.items()}
    return entry


def worn_summary(fig: dict, n_named: int) -> dict:
    """How a ring was worn over the sweep (accessories/wear), rest pose left out: its slide along the bone (mm,
    least and most), how many poses turned digits aside to make room for it (of them, how many in the named
    gestures), and the turn's median and largest angle (deg)."""
    slide, turned = (fig[k][1:] for k in ("slide", "turned"))
    moved = turned[turned > 0]
    return {"slide_mm": [round(float(slide.min(initial=0.0)) * 1000.0, 3),
                         round(float(slide.max(initial=0.0)) * 1000.0, 3)],
            "poses_turned": int(len(moved)), "gestures_turned": int((turned[:n_named - 1] > 0).sum()),
            "turned_median_deg": round(float(np.median(moved)), 3) if len(moved) else 0.0,
            "turned_max_deg": round(float(moved.max(initial=0.0)), 3)}


def _style(entry: dict) -> str:
    if entry["type"] == "watch":
        return f"{entry['case']}_{entry['strap']}"
    return str(entry["style"])


def _write_npz(path: Path, b: Built, world: np.ndarray, normals: np.ndarray, material: dict) -> None:
    m = b.mesh
    arrays: dict = dict(format=np.array(FORMAT), format_version=np.array(FORMAT_VERSION), id=np.array(b.id),
                  type=np.array(b.entry["type"]), vertices=world, local_vertices=m.vertices,
                  faces=m.faces.astype(np.int64), normals=normals, uvs=m.uvs, faces_uv=m.faces_uv.astype(np.int64),
                  parent_joint=np.array(-1 if b.fit is None else b.fit.joint, np.int64), rest_transform=b.rest,
                  material_json=np.array(json.dumps(material, sort_keys=True)))
    if m.skin is not None:
        arrays.update({k: m.skin[k] for k in ("weights", "posedirs", "shapedirs", "source_vertex", "layer")})
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    write_bytes(path, buf.getvalue())


def _obj_text(name: str, v, n, uv, f, fuv) -> str:
    lines = [f"# darthand accessory {name} (metres, rest pose, model frame)", f"mtllib {name}.mtl", f"o {name}"]
    lines += [f"v {x:.7f} {y:.7f} {z:.7f}" for x, y, z in v]
    lines += [f"vt {a:.6f} {c:.6f}" for a, c in uv]
    lines += [f"vn {x:.5f} {y:.5f} {z:.5f}" for x, y, z in n]
    lines.append(f"usemtl {name}")
    lines += [f"f {a + 1}/{ta + 1}/{a + 1} {b + 1}/{tb + 1}/{b + 1} {c + 1}/{tc + 1}/{c + 1}"
              for (a, b, c), (ta, tb, tc) in zip(f.tolist(), fuv.tolist())]
    return "\n".join(lines) + "\n"


def _mtl_text(name: str, material: dict, files: dict) -> str:
    return (f"newmtl {name}\nKd 1 1 1\nKs 0 0 0\nNs 10\nmap_Kd {files['base_color']}\n"
            f"Pm {material['metallic']:.3f}\nPr {material['roughness']:.3f}\n"
            f"# metallic-roughness texture (glTF layout): {files['metallic_roughness']}\n")


def write_image(path: str | Path, image: np.ndarray, srgb: bool) -> None:
    """Write a float image (H, W, 3) in [0, 1] as an 8-bit PNG, sRGB-encoded if `srgb` (albedo) else raw (data)."""
    data = linear_to_srgb(image) if srgb else np.clip(image, 0, 1)
    px = (np.asarray(data) * 255.0 + 0.5).astype(np.uint8)
    spec = oiio.ImageSpec(px.shape[1], px.shape[0], px.shape[2], oiio.UINT8)
    with atomic_path(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), spec) or not out.write_image(px) or not out.close():
            raise InputError(f"{path}: could not write PNG ({oiio.geterror()})")


# ---------------------------------------------------------------- contact sheet
def write_contact_sheet(model: HandModel, built: list[Built], path: Path, tile: int = 192) -> None:
    """All accessories on the rest hand, one tile each (rings close up from the back of the hand, wrist items
    three-quarter, gloves the whole hand), labelled with their ids."""
    hand = {"vertices": model.v_template, "faces": model.faces}
    images, labels = [], []
    for b in built:
        m = b.mesh
        acc = {"vertices": b.world_vertices, "faces": m.faces, "uvs": m.uvs, "faces_uv": m.faces_uv,
               "texture": m.textures["base_color"], "metallic": float(m.material.get("metallic", 0.0))}
        if b.entry["type"] == "ring":
            centre, view, extent = b.rest[:3, 3], (-0.3, -1.0, -0.5), 0.06
        elif b.entry["type"] == "glove":
            centre, view, extent = model.v_template.mean(0), (0.0, -1.0, -0.15), 0.24
        else:
            centre, view, extent = b.rest[:3, 3], (-0.4, -0.8, -0.6), 0.13
        images.append(render_view([hand, acc], centre, view, (-1.0, 0.0, 0.0), extent, tile))
        labels.append(b.id[:26])
    write_png(path, contact_sheet(images, labels, cols=10))
