"""The objects stage: generate or import each catalogue item, check it, write it and the catalogue.

Per object `build/objects/<id>.npz` (written byte-reproducibly: fixed zip dates), float64/int32, no pickles:
  vertices (N, 3) metres, object frame (origin at the bounding box's centre, +z the object's axis or thin axis)
  faces (F, 3) int32 outward (counter-clockwise seen from outside), the mesh closed
  face_part (F,) int16 index into the entry's parts
  uvs (T, 2) float32, faces_uv (F, 3) int32   when the object has a base-colour texture (<id>_albedo.png, sRGB)
and catalog.json (schemas/object_catalog.schema.json), licences/ (the licence files of vendored items) and
contact_sheet.png.
"""

from __future__ import annotations

import concurrent.futures as cf
import io
import multiprocessing
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import file_in, read_bytes, write_bytes, write_json
from darthand.objects import catalog as cat
from darthand.objects.checks import check_licence, check_mesh
from darthand.objects.generators import KINDS, Shape, part
from darthand.objects.preview import object_tile, size_label, write_sheet
from darthand.objects.vendored import load_vendored
from darthand.processes import deaf_to_ctrl_c, init_worker
from darthand.schemas import check_schema

FORMAT, FORMAT_VERSION = "darthand-objects", 1
ZIP_DATE = (1980, 1, 1, 0, 0, 0)


@dataclass
class Built:
    """One object ready to write: its catalogue fields and arrays (see the module docstring), the texture it
    copies (a path) and the licence file it ships, if any."""

    item: dict
    shape: Shape
    uvs: np.ndarray | None = None
    faces_uv: np.ndarray | None = None
    texture: Path | None = None
    licence_file: Path | None = None
    repairs: list[str] = field(default_factory=list)


# ---------------------------------------------------------------- the stage
def build_objects(spec: dict, out_dir: str | Path, spec_dir: str | Path, ids=None, *, jobs: int = 1,
                  sheet: bool = True, tile: int = 192, source: str = "catalogue spec") -> dict:
    """Build the spec's objects (or the `ids` subset) into `out_dir`; return and write catalog.json. An item that
    fails a check is listed in `skipped` with why and the build goes on; InputError when none is usable.
    `spec_dir` is where the spec's relative paths (vendored meshes, textures, licences) start; `jobs` processes
    build the items."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    items = cat.select(spec, ids)
    jobs_args = [(spec, item, str(spec_dir), str(out_dir), source, tile if sheet else 0) for item in items]
    results = list(_run(jobs_args, jobs))
    entries = [r[0] for r in results if "why" not in r[0]]
    skipped = [r[0] for r in results if "why" in r[0]]
    if not entries:
        first = f" (first: {skipped[0]['id']}: {skipped[0]['why']})" if skipped else ""
        raise InputError(f"{source}: no usable object{first}")
    sheet_name = None
    if sheet:
        sheet_name = "contact_sheet.png"
        tiles = [(r[1], size_label(r[0]["id"], r[0]["size_m"])) for r in results if r[1] is not None]
        write_sheet(out_dir / sheet_name, [t for t, _ in tiles], [lab for _, lab in tiles])
    catalog = {"format": FORMAT, "format_version": FORMAT_VERSION, "seed": int(spec["seed"]), "objects": entries,
               "skipped": skipped, "contact_sheet": sheet_name}
    check_schema(catalog, "object_catalog.schema.json", str(out_dir / "catalog.json"))
    write_json(out_dir / "catalog.json", catalog)
    return catalog


def _run(jobs_args: list, jobs: int):
    """Each item's (entry or skip record, tile or None), in spec order; in `jobs` processes when jobs > 1."""
    if jobs <= 1 or len(jobs_args) <= 1:
        yield from (build_one(a) for a in jobs_args)
        return
    ctx = multiprocessing.get_context("spawn")
    with cf.ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=init_worker,
                                initargs=(os.getpid(),)) as pool:
        with deaf_to_ctrl_c():
            futures = [pool.submit(build_one, a) for a in jobs_args]
        yield from (f.result() for f in futures)


def build_one(args) -> tuple[dict, np.ndarray | None]:
    """Make, check and write one item: (its catalogue entry, its contact-sheet tile), or ({id, why}, None) when
    a check refuses it."""
    spec, item, spec_dir, out_dir, source, tile = args
    try:
        built = make_object(spec, item, Path(spec_dir), f"{source}: object {item['id']!r}")
    except InputError as e:
        return {"id": item["id"], "why": str(e).split(": ", 2)[-1]}, None
    entry = write_object(Path(out_dir), built, cat.grasps_for(spec, item))
    s = built.shape
    image = None
    if tile:
        png = None if built.texture is None else Path(out_dir) / entry["files"]["base_color"]
        image = object_tile(s.vertices, s.faces, s.face_part, s.parts, built.uvs, built.faces_uv, png, tile)
    return entry, image


def make_object(spec: dict, item: dict, spec_dir: Path, where: str) -> Built:
    """The item generated (a procedural kind) or imported (kind 'mesh'), centred on its bounding box and checked:
    InputError naming it when its licence is not allowed or its mesh is not closed, not finite or of an absurd
    size."""
    check_licence(item.get("licence", "CC0-1.0"), where)
    if item["kind"] == "mesh":
        built = _imported(item, spec_dir, where)
    else:
        built = Built(item, KINDS[item["kind"]](cat.resolve(spec, item)))
    s = built.shape
    if len(s.vertices) and np.isfinite(s.vertices).all():
        s.vertices = s.vertices - (s.vertices.min(axis=0) + s.vertices.max(axis=0)) / 2
    check_mesh(s.vertices, s.faces, where)
    return built


def _imported(item: dict, spec_dir: Path, where: str) -> Built:
    """A vendored mesh (`mesh`, scaled by `scale`, closed when `repair` allows), one part in the item's colour,
    textured by `texture` when given."""
    mesh_path = file_in(spec_dir, item["mesh"], "object mesh")
    mesh = load_vendored(mesh_path, item.get("scale", [1.0, 1.0, 1.0]), bool(item.get("repair", False)), where)
    texture = file_in(spec_dir, item["texture"], "object texture") if item.get("texture") else None
    licence = file_in(spec_dir, item["licence_file"], "licence file") if item.get("licence_file") else None
    p = part("body", item.get("color", [0.8, 0.8, 0.8]), item.get("roughness", 0.5), item.get("metallic", 0.0))
    shape = Shape(mesh.vertices, mesh.faces, np.zeros(len(mesh.faces), np.int16), [p])
    textured = texture is not None and mesh.uvs is not None
    return Built(item, shape, mesh.uvs if textured else None, mesh.faces_uv if textured else None,
                 texture if textured else None, licence, mesh.repairs)


# ---------------------------------------------------------------- files
def write_object(out_dir: Path, b: Built, grasps: list[str]) -> dict:
    """Write one object's npz (and texture and licence copies); return its catalogue entry, listing the grasp
    types (taxonomy names) it suits."""
    item, s = b.item, b.shape
    files: dict = {"npz": f"{item['id']}.npz", "base_color": None}
    arrays = {"vertices": np.asarray(s.vertices, np.float64), "faces": np.asarray(s.faces, np.int32),
              "face_part": np.asarray(s.face_part, np.int16)}
    if b.texture is not None and b.uvs is not None and b.faces_uv is not None:
        files["base_color"] = f"{item['id']}_albedo.png"
        write_bytes(out_dir / files["base_color"], read_bytes(b.texture, "object texture"))
        arrays.update(uvs=np.asarray(b.uvs, np.float32), faces_uv=np.asarray(b.faces_uv, np.int32))
    write_bytes(out_dir / files["npz"], npz_bytes(arrays))
    licence_file = None
    if b.licence_file is not None:
        licence_file = f"licences/{item.get('source', 'vendored')}-{b.licence_file.name}"
        (out_dir / "licences").mkdir(exist_ok=True)
        write_bytes(out_dir / licence_file, read_bytes(b.licence_file, "licence file"))
    size = np.ptp(s.vertices, axis=0)
    entry = {"id": item["id"], "category": item["category"], "name": item["name"], "kind": item["kind"],
             "source": item.get("source", "procedural"), "licence": item.get("licence", "CC0-1.0"),
             "licence_file": licence_file, "size_m": [round(float(x), 6) for x in size],
             "grasps": list(grasps), "files": files, "parts": s.parts,
             "vertices": int(len(s.vertices)), "triangles": int(len(s.faces))}
    if b.repairs:
        entry["repairs"] = list(b.repairs)
    return entry


def npz_bytes(arrays: dict) -> bytes:
    """An uncompressed-header, deflated .npz of `arrays` whose bytes depend only on the arrays (np.savez stamps the
    current time into the zip)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, array in arrays.items():
            data = io.BytesIO()
            np.lib.format.write_array(data, np.ascontiguousarray(array), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=ZIP_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            z.writestr(info, data.getvalue())
    return buf.getvalue()
