"""Build the texture catalogue (or a subset) into a folder: per-variant albedo PNG, roughness PNG, mip-mapped
.tx, plus catalog.json, the baked label and coverage maps, and the contact sheet.

Layout of `out_dir` (build/textures/):
    <id>.png                 sRGB albedo, 8-bit
    <id>.tx                  the same, tiled and mip-mapped (imageio.write_tx)
    roughness_<hash>.png     roughness (raw, 8-bit); variants with identical roughness share one file
    labels_<res>.png         semantic label per texel (layout.FACE_LABELS index, 255 = no surface)
    coverage_<res>.png       255 where a texel centre lies on the surface
    bake_<res>.npz           cached baked maps (an internal cache)
    model_uv.npz             the model with its generated atlas (only when the model came without UVs)
    catalog.json             the catalogue (schemas/texture_catalog.schema.json)
    contact_sheet.png        every listed variant as a thumbnail

Variants are rendered in parallel processes; each process loads the bake once. An entry whose fingerprint and
files match the existing catalog.json is not rendered again (unless `force`). Building a subset renders only
the subset; catalog.json keeps listing the up-to-date entries built before.
"""

from __future__ import annotations

import concurrent.futures as cf
import functools
import hashlib
import json
import multiprocessing
import os
import sys
import time
from pathlib import Path

import numpy as np

from darthand.budget import check_memory
from darthand.errors import InputError
from darthand.fileio import file_in, read_json, sha256_file, write_json
from darthand.model.hand_model import HandModel
from darthand.processes import deaf_to_ctrl_c, init_worker, keep_freed_memory
from darthand.textures import sheet as sheet_mod
from darthand.model.atlas import ensure_uvs
from darthand.model.npz_io import save_npz
from darthand.textures.bake import Bake, cached_bake, load_bake, source_digest
from darthand.textures.catalog import Entry, expand_catalog, select
from darthand.textures.imageio import block_mean, mip_pyramid, read_small, write_png, write_tx
from darthand.textures.variant import render_variant

CATALOG_FORMAT = "darthand-texture-catalog"
CATALOG_VERSION = 1
# Every module of the stage can change an image: their source is part of each entry's fingerprint.
RENDER_MODULES = ("anatomy", "bake", "canvas", "catalog", "color", "curves", "imageio", "motifs", "noise",
                  "overlays", "padding", "raster", "model/regions", "sampling", "skin", "surface", "variant")
THUMB_SOURCE = 512  # size of the albedo copy a contact-sheet tile samples
# Peak memory per texel of each process (the bake and one variant's layers; measured about 92 bytes from 1024 to 2048).
BYTES_PER_TEXEL = 100


def build_textures(model: HandModel, spec: dict, out_dir: str | Path, res: int = 2048, ids=None, categories=None,
                   workers: int = 2, progress: bool = True, tx: bool = True, roughness: bool = True,
                   sheet: bool = True, force: bool = False) -> dict:
    """Render the selected catalogue entries of `spec` for `model` into `out_dir`; return the catalog dict
    (also written to out_dir/catalog.json)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    res = int(res)
    check_memory(f"{res}x{res} textures in {max(workers, 1)} worker processes",
                 BYTES_PER_TEXEL * res * res * (1 + max(workers, 1)))
    entries = expand_catalog(spec)
    chosen = select(entries, ids, categories)
    had_uvs = model.has_uvs
    model = ensure_uvs(model, res)
    if not had_uvs:
        save_npz(model, out_dir / "model_uv.npz")
    bake, bake_path = cached_bake(model, res, out_dir)
    maps = write_bake_maps(bake, out_dir)
    previous = _previous_records(out_dir / "catalog.json", res)
    records = {}
    todo = []
    for e in chosen:
        fp = fingerprint(e, res, bake.key, tx, roughness)
        old = previous.get(e.id)
        if not force and old and old.get("fingerprint") == fp and _files_intact(out_dir, old):
            records[e.id] = old
        else:
            todo.append(e)
    tiles = {}
    for record, tile in _render_all(todo, bake, bake_path, out_dir, res, tx, roughness, workers, progress):
        records[record["id"]] = record
        tiles[record["id"]] = tile
    # Keep earlier entries that are still valid; list everything in catalogue order.
    for e in entries:
        old = previous.get(e.id)
        if e.id not in records and old and old.get("fingerprint") == fingerprint(e, res, bake.key, tx, roughness) \
                and _files_intact(out_dir, old):
            records[e.id] = old
    listed = [records[e.id] for e in entries if e.id in records]
    catalog = {
        "format": CATALOG_FORMAT, "version": CATALOG_VERSION, "resolution": res, "seed": int(spec["seed"]),
        "spec_sha256": hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest(),
        "bake": {"key": bake.key, "uvs": "xatlas" if not had_uvs else "model", **maps},
        "model": {"source": str(model.meta.get("source", "model")), "vertices": model.num_vertices,
                  "faces": model.num_faces},
        "contact_sheet": "contact_sheet.png" if sheet and listed else None,
        "entries": listed,
    }
    if spec.get("default") in {r["id"] for r in listed}:
        catalog["default"] = spec["default"]
    if sheet and listed:
        make_contact_sheet(out_dir, catalog, bake, tiles)
    write_json(out_dir / "catalog.json", catalog)
    return catalog


def fingerprint(entry: Entry, res: int, bake_key: str, tx: bool, roughness: bool) -> str:
    """What an entry's files depend on: the entry, the resolution, the bake, the outputs asked for, the code."""
    h = hashlib.sha256(entry.fingerprint().encode())
    h.update(f"|{res}|{bake_key}|tx={tx}|roughness={roughness}|{_render_code()}".encode())
    return h.hexdigest()


@functools.lru_cache(maxsize=1)
def _render_code() -> str:
    return source_digest(RENDER_MODULES)


def write_bake_maps(bake: Bake, out_dir: Path) -> dict:
    """Write the label and coverage maps of a bake (once per resolution); return their file names."""
    labels, coverage = f"labels_{bake.res}.png", f"coverage_{bake.res}.png"
    write_png(out_dir / labels, bake.label_image(), srgb=False)
    write_png(out_dir / coverage, bake.coverage().astype(np.uint8) * 255, srgb=False)
    return {"labels": labels, "coverage": coverage}


def _previous_records(path: Path, res: int) -> dict:
    if not path.is_file():
        return {}
    try:
        old = read_json(path, "texture catalogue")
    except InputError:              # an unreadable previous catalogue: every entry is rendered again
        return {}
    if not isinstance(old, dict) or old.get("format") != CATALOG_FORMAT or old.get("resolution") != res \
            or not isinstance(old.get("entries"), list):
        return {}
    return {r["id"]: r for r in old["entries"] if isinstance(r, dict) and isinstance(r.get("id"), str)}


def _files_intact(out_dir: Path, record: dict) -> bool:
    """The entry's files are regular files in `out_dir` and its albedo has the recorded sha256."""
    files = record.get("files")
    if not isinstance(files, dict) or not isinstance(files.get("albedo"), str):
        return False
    try:
        paths = [file_in(out_dir, f, "texture") for f in files.values() if f]
    except (InputError, TypeError):        # missing, or a name leading out of the folder: render it again
        return False
    return bool(paths) and sha256_file(out_dir / files["albedo"]) == record.get("sha256")


# ------------------------------------------------------------------------------------------ rendering
_WORKER_BAKE: Bake | None = None


def _init_worker(bake_path: str, parent: int) -> None:
    global _WORKER_BAKE
    init_worker(parent)   # Ctrl-C is the parent's to handle; the worker ends with its parent (even one that died
                          # while this worker was starting: the pid is the parent's, not whoever adopted us)
    keep_freed_memory()   # every variant makes and drops the same few-MB arrays: reuse them, not fresh pages
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import OpenImageIO as oiio

    oiio.attribute("threads", 1)  # parallelism is across variants; keep each process on one core
    _WORKER_BAKE = load_bake(bake_path)


def _render_all(todo, bake, bake_path, out_dir, res, tx, roughness, workers, progress):
    """Yield (record, contact-sheet tile) for every entry in `todo`, rendering in `workers` processes (in this
    process when workers <= 1)."""
    bar = Progress(len(todo), enabled=progress)
    if not todo:
        return
    jobs = [(e.to_json(), str(out_dir), res, bake.key, tx, roughness) for e in todo]
    if workers <= 1 or len(todo) == 1:
        global _WORKER_BAKE
        _WORKER_BAKE = bake
        for job in jobs:
            result = _render_one(job)
            bar.step(result[0]["id"])
            yield result
        bar.done()
        return
    ctx = multiprocessing.get_context("spawn")  # no forked copies of OpenImageIO's threads
    with cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker,
                                initargs=(str(bake_path), os.getpid())) as pool:
        with deaf_to_ctrl_c():                  # submit starts the workers; Ctrl-C is ours, even while they import
            futures = [pool.submit(_render_one, job) for job in jobs]
        try:
            for fut in cf.as_completed(futures):
                result = fut.result()
                bar.step(result[0]["id"])
                yield result
        except BaseException:         # Ctrl-C or a failed variant: running ones finish (atomic files), none start
            pool.shutdown(wait=True, cancel_futures=True)
            raise
    bar.done()


def _render_one(job) -> tuple[dict, np.ndarray]:
    """Render one entry and write its files; return its catalog record and its contact-sheet tile (made here, in
    the worker, rather than all at the end in the parent)."""
    entry_json, out_dir, res, bake_key, tx, roughness = job
    entry = Entry(**entry_json)
    out_dir = Path(out_dir)
    assert _WORKER_BAKE is not None, "the pool's initializer loads the bake"
    v = render_variant(_WORKER_BAKE, entry)
    files: dict = {"albedo": f"{entry.id}.png", "roughness": None, "tx": None}
    write_png(out_dir / files["albedo"], v.albedo)
    record = {k: entry_json[k] for k in ("id", "category", "kind", "tone", "mst", "tone_srgb", "offset", "seed",
                                         "index")}
    if roughness:
        digest = hashlib.sha256(v.roughness.tobytes()).hexdigest()
        files["roughness"] = f"roughness_{digest[:16]}.png"
        if not (out_dir / files["roughness"]).is_file():  # shared by every variant with the same roughness
            write_png(out_dir / files["roughness"], v.roughness, srgb=False)
        record["roughness_sha256"] = sha256_file(out_dir / files["roughness"])
    levels = mip_pyramid(v.albedo) if tx else None          # the .tx's levels; one of them is the thumbnail's
    if tx:
        files["tx"] = f"{entry.id}.tx"
        write_tx(out_dir / files["tx"], v.albedo, levels=levels)
    else:
        (out_dir / f"{entry.id}.tx").unlink(missing_ok=True)  # an earlier build's, now out of date
    record.update(resolution=res, sha256=sha256_file(out_dir / files["albedo"]), files=files,
                  params=entry_json["params"], fingerprint=fingerprint(entry, res, bake_key, tx, roughness))
    thumb = next((lv for lv in levels if lv.shape[1] <= THUMB_SOURCE), None) if levels else None
    return record, sheet_mod.thumbnail(block_mean(v.albedo, THUMB_SOURCE) if thumb is None else thumb,
                                       _preview_maps(_WORKER_BAKE))


_PREVIEW_MAPS: tuple = (None, None)


def _preview_maps(bake: Bake) -> sheet_mod.PreviewMaps:
    """The contact sheet's preview lookups of `bake`'s mesh, made once per process and bake."""
    global _PREVIEW_MAPS
    if _PREVIEW_MAPS[0] is not bake:
        _PREVIEW_MAPS = (bake, sheet_mod.preview_maps(bake.mesh))
    return _PREVIEW_MAPS[1]


# ------------------------------------------------------------------------------------------ contact sheet
def make_contact_sheet(out_dir: str | Path, catalog: dict, bake: Bake | None = None,
                       tiles: dict | None = None) -> Path:
    """Write out_dir/contact_sheet.png from the catalog's entries, grouped by category: the tiles given (by id,
    made by the workers), else tiles made here from the files on disk (the .tx's matching MIP level when there is
    one)."""
    out_dir = Path(out_dir)
    tiles = tiles or {}
    missing = [r for r in catalog["entries"] if r["id"] not in tiles]
    if missing and bake is None:
        bake_path = out_dir / f"bake_{catalog['resolution']}.npz"
        if not bake_path.is_file():
            raise InputError(f"{bake_path}: no baked maps for the contact sheet; run 'darthand textures build' first")
        bake = load_bake(bake_path)
    for record in missing:
        assert bake is not None
        f = record["files"].get("tx") or record["files"]["albedo"]
        tiles[record["id"]] = sheet_mod.thumbnail(read_small(out_dir / f, THUMB_SOURCE), _preview_maps(bake))
    path = out_dir / "contact_sheet.png"
    sheet_mod.contact_sheet([(sheet_mod.group_name(r), sheet_mod.describe(r), tiles[r["id"]])
                             for r in catalog["entries"]], path)
    return path


class Progress:
    """A text progress bar on stderr: done/total, bar, time per variant, time left. Redrawn in place on a
    terminal; otherwise one line per tenth of the work (so logs stay short)."""

    def __init__(self, total: int, enabled: bool = True, label: str = "textures"):
        self.total, self.enabled, self.label = total, enabled and total > 0, label
        self.done_count = 0
        self.start = time.perf_counter()
        self.tty = sys.stderr.isatty()
        self.last_decile = -1

    def step(self, name: str = "") -> None:
        self.done_count += 1
        if not self.enabled:
            return
        decile = 10 * self.done_count // self.total
        if not self.tty and decile == self.last_decile:
            return
        self.last_decile = decile
        elapsed = time.perf_counter() - self.start
        rate = elapsed / self.done_count
        left = rate * (self.total - self.done_count)
        width = 28
        fill = int(width * self.done_count / self.total)
        line = (f"[{self.label}] {self.done_count}/{self.total} [{'#' * fill}{'.' * (width - fill)}] "
                f"{rate:.2f} s/variant, {left:4.0f} s left  {name[:28]:<28}")
        sys.stderr.write(f"\r{line}" if self.tty else f"{line.rstrip()}\n")
        sys.stderr.flush()

    def done(self) -> None:
        if self.enabled:
            elapsed = time.perf_counter() - self.start
            line = f"[{self.label}] {self.total} variants in {elapsed:.1f} s"
            sys.stderr.write(f"\r{line}{' ' * 60}\n" if self.tty else f"{line}\n")
            sys.stderr.flush()
