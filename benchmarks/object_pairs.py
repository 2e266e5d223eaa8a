"""Two hands on one object (issue 30: the `held` and `handover` interaction types, dataset/object_pairs.py), next to
the one-hand object frames of benchmarks/object_dataset.py (whose run it reuses): `render-dataset --two-hands 1
--interactions held=0.5,handover=0.5` against `--objects 1`, the dataset defaults, 512^2, the build's catalogues.

Figures: the pair table's CPU (which right/left grasp pairs suit each object, once per plan), planning CPU per frame
of each type (the main process's share), redraws and fallbacks per type, penetration measured again on the planned
jobs (hand into object by render/object_contacts' exact distances and winding numbers, hand into hand by
model/hand_pair's depths and MeshLab's crossing faces: max and p99 over frames), the images per second of both runs
and their ratio, and a contact sheet of the first 16 rendered frames of each type (object_pairs_sheet.jpg in the
output folder). DARTHAND_BENCH_PAIR_FRAMES sets the frames per run and planned (default 100). `table_or_not`
(DARTHAND_BENCH_PAIR_DRAWS draws, default 40) weighs the pair table against drawing any pair and rejecting: the
share of draws that pass and the CPU per frame drawn, each way.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.object_dataset import _catalogs, _run
from benchmarks.render_dataset import dataset_inputs

TYPES = ("held", "handover")
SHEET_PER_TYPE = 16
TILE = 256


def _planner(model, textures, accessories, shares: dict):
    from darthand.dataset.plan import Planner, PlanOptions
    from darthand.dataset.sources import source_specs

    catalog, grasps = _catalogs()
    specs = source_specs(str(model), ("right", "left"), textures=str(textures), accessories=str(accessories))
    sources = {side: spec.open() for side, spec in specs.items()}
    t = time.process_time()
    planner = Planner({**PlanOptions(two_hands=1.0, interactions=shares).spec(), "sides": list(sources)}, sources,
                      {"objects": catalog, "grasps": grasps})
    return planner, sources, time.process_time() - t


def _planning(model, textures, accessories, frames: int) -> dict:
    """Per type: CPU ms per frame, redraws, fallbacks and the penetration figures of `frames` planned frames."""
    out: dict = {}
    for kind in TYPES:
        planner, sources, setup = _planner(model, textures, accessories, {kind: 1.0})
        planner.job(0)                                                      # compile before timing
        t = time.process_time()
        jobs = list(planner.jobs(1, frames + 1))
        cpu = time.process_time() - t
        done = [j for j in jobs if j["interaction"]["type"] == kind]
        out[kind] = {"cpu_ms_per_frame": round(1000 * cpu / len(jobs), 1), "frames": len(jobs),
                     "redraws": sum(j["interaction"]["attempts"] - 1 for j in done),
                     "fallbacks": len(jobs) - len(done), "plan_setup_cpu_s": round(setup, 2),
                     "pair_table": planner.pairs.objects.table.describe(),
                     "categories": _count(j["interaction"]["object"]["category"] for j in done),
                     **_penetration(done, sources)}
    return out


def _penetration(jobs: list, sources: dict) -> dict:
    """Max and p99 (mm, over frames) of each frame's deepest hand vertex in its object and its hands' depth into
    each other, and the frames with MeshLab crossing faces between the hands, measured again from the jobs."""
    from darthand.model.hand_pair import pose_hand, penetration
    from darthand.render.object_contacts import object_contacts
    from darthand.render.objects import ObjectLibrary

    library = ObjectLibrary.load(_catalogs()[0])
    object_mm, hand_mm, crossing = [], [], 0
    for job in jobs:
        right, left, held = job["bodies"]
        hands = [pose_hand(sources[b["side"]].pose_model(), b["pose"], b.get("betas"),
                           np.asarray(b.get("placement", np.eye(4)))) for b in (right, left)]
        item, P = library.item(held["object"]), np.asarray(held["placement"])
        object_mm.append(1000 * max(object_contacts(h.vertices, item, P).penetration_max_m for h in hands))
        found = penetration(*hands)
        hand_mm.append(1000 * found.max_m)
        crossing += found.crossing_faces > 0
    figures = lambda x: {"max": round(float(np.max(x, initial=0)), 3),
                         "p99": round(float(np.percentile(x, 99)), 3) if x else 0.0}
    return {"hand_object_mm": figures(object_mm), "hand_hand_mm": figures(hand_mm), "frames_crossing": crossing}


def table_or_not(draws: int) -> dict:
    """Per type, with the pair table and without it (any right/left pair of an object of MIN_EXTENT_M or more):
    draws that pass the frame's checks, CPU ms a draw and per frame drawn; and the table's set-up CPU."""
    from darthand.dataset import object_pairs as op
    from darthand.model.load import load_model

    model = dataset_inputs(Path(tempfile.gettempdir()))[0]
    right, left = load_model(str(model)), load_model(str(Path(model).with_name("left.npz")))
    pairs = op.ObjectPairs(*_catalogs(), right, left)
    frames, table = pairs.frames, pairs.table.pairs
    grasps = frames.grasps
    everything = {i: [(a, b) for a in range(len(grasps["right"][i])) for b in range(len(grasps["left"][i]))]
                  for i in sorted(frames.items) if i in grasps["right"] and i in grasps["left"]
                  and np.ptp(frames.items[i].vertices, axis=0).max() >= op.MIN_EXTENT_M}
    models = {s: frames.models[s] for s in op.SIDES}
    out: dict = {"table": pairs.table.describe()}
    for name, chosen in (("table", table), ("no_table", everything)):
        pairs.table.pairs, pairs.ids = chosen, sorted(chosen)
        for kind in TYPES:
            t, ok = time.process_time(), 0
            for i in range(draws):
                ok += pairs.draw(kind, np.random.default_rng([7, i]).random(op.PAIR_UNIFORMS), models) is not None
            cpu = time.process_time() - t
            out[f"{name}_{kind}"] = {"pass": ok, "draws": draws, "cpu_ms_a_draw": round(1000 * cpu / draws),
                                     "cpu_ms_a_frame": round(1000 * cpu / max(ok, 1))}
    return out


def _count(values) -> dict:
    out: dict = {}
    for v in values:
        out[v] = out.get(v, 0) + 1
    return dict(sorted(out.items()))


def contact_sheet(dataset: Path, path: Path) -> dict:
    """path: the first SHEET_PER_TYPE frames of each type (a row of 8 tiles, the frame, type and object on each);
    returns the frames shown per type."""
    from PIL import Image, ImageDraw

    by_type: dict = {k: [] for k in TYPES}
    for labels_file in sorted((dataset / "labels").glob("*.json")):
        labels = json.loads(labels_file.read_text())
        kind = (labels.get("interaction") or {}).get("type")
        if kind in by_type and len(by_type[kind]) < SHEET_PER_TYPE:
            by_type[kind].append((labels_file.stem, labels))
    tiles = []
    for kind in TYPES:
        for stem, labels in by_type[kind]:
            image = Image.open(dataset / "images" / f"{stem}.png").convert("RGB").resize((TILE, TILE))
            draw = ImageDraw.Draw(image)
            entry = labels["objects"][0]
            grasps = "/".join(g["type"] for g in entry.get("grasps", ()))
            draw.rectangle((0, 0, TILE, 24), fill=(0, 0, 0))
            draw.text((3, 1), f"{stem} {kind} {entry['id']}", fill=(255, 255, 0))
            draw.text((3, 12), grasps[:42], fill=(200, 200, 200))
            tiles.append(np.asarray(image))
    columns = 8
    while len(tiles) % columns:
        tiles.append(np.zeros((TILE, TILE, 3), np.uint8))
    rows = [np.concatenate(tiles[i:i + columns], 1) for i in range(0, len(tiles), columns)]
    Image.fromarray(np.concatenate(rows, 0)).save(path, quality=88)
    return {k: len(v) for k, v in by_type.items()}


def run(out: Path) -> dict:
    frames = int(os.environ.get("DARTHAND_BENCH_PAIR_FRAMES", 100))
    table = table_or_not(int(os.environ.get("DARTHAND_BENCH_PAIR_DRAWS", 40)))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        model, textures, accessories, where = dataset_inputs(tmp)
        plan = _planning(model, textures, accessories, frames)
        one = _run(model, textures, accessories, tmp / "one", frames, 1.0)
        pairs = _run(model, textures, accessories, tmp / "pairs", frames, 0.0, two_hands=1.0,
                     interactions={k: 0.5 for k in TYPES})
        Path(out).mkdir(parents=True, exist_ok=True)
        shown = contact_sheet(tmp / "pairs", Path(out) / "object_pairs_sheet.jpg")
    ratio = (pairs["images_per_second"] or 0) / max(1e-9, one["images_per_second"] or 0)
    return {"pair_vs_one_hand_object_rate": round(ratio, 3), "frames": frames, "inputs": where,
            "catalogs": list(_catalogs()), "one_hand_objects": one, "two_hands_one_object": pairs,
            "planning": plan, "table_or_not": table,
            "sheet": {"file": "object_pairs_sheet.jpg", "frames_per_type": shown}}


def summary(result: dict) -> str:
    one, pairs, plan = result["one_hand_objects"], result["two_hands_one_object"], result["planning"]
    lines = [f"**Two hands on one object at {result['pair_vs_one_hand_object_rate']:.2f} of the one-hand object "
             f"rate**: {pairs['images_per_second']} against {one['images_per_second']} images/s, {result['frames']} "
             f"frames each, 512^2, the dataset defaults, {result['inputs']}.", ""]
    for kind, p in plan.items():
        lines.append(f"- {kind}: planning {p['cpu_ms_per_frame']} ms CPU a frame ({p['frames']} frames; plan set-up "
                     f"{p['plan_setup_cpu_s']} s with the pair table {p['pair_table']}), {p['redraws']} redraws, "
                     f"{p['fallbacks']} fallbacks; penetration hand-object {p['hand_object_mm']} mm, hand-hand "
                     f"{p['hand_hand_mm']} mm, {p['frames_crossing']} frames with crossing faces; categories "
                     f"{p['categories']}.")
    if "table_or_not" in result:
        lines.append(f"- pair table against drawing any pair and rejecting: {result['table_or_not']}")
    return "\n".join(lines)
