"""Benchmark of the grasp stage: the fit time per object and grasp type, the refit time per hand shape (the
per-frame step), penetration and contact figures over a catalogue, and the stage's build time, over one object of
each category of the built object catalogue (build/objects, else one built here) on `make assets`' models (else
the open hand and its mirror image). Seconds of wall time, single process; CPU seconds beside them."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks._common import bench_model
from darthand.grasps.build import build_grasps
from darthand.grasps.loader import load_grasp_catalog
from darthand.grasps.refit import REFIT_NFEV, REFIT_PENETRATION, REFIT_ROUNDS, object_field, refit_grasp
from darthand.model.mirror import mirror_model
from darthand.model.npz_io import save_npz
from darthand.objects import catalog as cat
from darthand.objects.build import build_objects
from darthand.objects.loader import load_object_catalog

BUILT_OBJECTS = Path("build/objects/catalog.json")
SHAPES = 10          # sampled shapes each grasp is refitted to
REFITS = 12          # grasps refitted (spread over the categories)


def one_per_category(items) -> list:
    seen: dict = {}
    for it in items:
        seen.setdefault(it.category, it)
    return list(seen.values())


def run() -> dict:
    model, model_name = bench_model()
    with tempfile.TemporaryDirectory() as tmp:
        if BUILT_OBJECTS.is_file():
            items = load_object_catalog(BUILT_OBJECTS)
        else:
            build_objects(cat.load_spec(), Path(tmp) / "objects", cat.DEFAULT_SPEC.parent, sheet=False)
            items = load_object_catalog(Path(tmp) / "objects")
        every = len(items)
        items = one_per_category(items)
        paths = {"right": str(Path(tmp) / "right.npz"), "left": str(Path(tmp) / "left.npz")}
        save_npz(model, paths["right"])
        save_npz(mirror_model(model), paths["left"])
        t0, c0 = time.perf_counter(), time.process_time()
        timing: dict = {}
        doc = build_grasps(items, paths, Path(tmp) / "grasps", sheet=False, timing=timing)
        build_s, build_cpu = time.perf_counter() - t0, time.process_time() - c0
        grasps = load_grasp_catalog(Path(tmp) / "grasps")
    right = [g for g in doc["grasps"] if g["side"] == "right"]
    per_type: dict = {}
    per_object: dict = {}
    for object_id, type_, side, seconds in timing["fits"]:
        if side == "right":
            per_type.setdefault(type_, []).append(seconds)
            per_object.setdefault(object_id, []).append(seconds)
    pens = np.array([g["figures"]["penetration_max_mm"] for g in doc["grasps"]])
    gaps = np.array([abs(v) for g in doc["grasps"] for v in g["figures"]["contact_mm"].values()])
    return {"model": model_name, "objects": [it.id for it in items],
            "stage": {"build_s": round(build_s, 2), "build_cpu_s": round(build_cpu, 2),
                      "fits_per_side": len(right) + sum(d["side"] == "right" for d in doc["dropped"]),
                      "per_object_s": round(build_s / len(items), 2),
                      "catalogue_objects": every,
                      "catalogue_estimate_s": round(build_s / len(items) * every, 1)},
            "fit_s": {"median": round(float(np.median(sum(per_type.values(), []))), 3),
                      "per_type_mean": {k: round(float(np.mean(v)), 3) for k, v in sorted(per_type.items())},
                      "per_object_mean": {k: round(float(np.mean(v)), 3) for k, v in sorted(per_object.items())}},
            "refit": refit_times(model, items, grasps),
            "figures": {"fitted": doc["counts"]["fitted"], "dropped": doc["counts"]["dropped"],
                        "dropped_why": sorted({d["why"].split(" (")[0].split(" ")[0] for d in doc["dropped"]}),
                        "penetration_max_mm": round(float(pens.max(initial=0.0)), 3),
                        "penetration_p99_mm": round(float(np.percentile(pens, 99)), 3) if len(pens) else 0.0,
                        "contact_median_mm": round(float(np.median(gaps)), 3) if len(gaps) else 0.0,
                        "contact_p99_mm": round(float(np.percentile(gaps, 99)), 3) if len(gaps) else 0.0,
                        "contact_max_mm": round(float(gaps.max(initial=0.0)), 3)}}


def refit_times(model, items, grasps) -> dict:
    """Refit REFITS right-hand grasps to SHAPES sampled shapes each: wall and CPU ms per refit, how many stay
    within the drop rule and within a planned frame's 1 mm (REFIT_PENETRATION), how many took the second pass, and
    the penetration after refitting."""
    rng = np.random.default_rng(0)
    by_id = {it.id: it for it in items}
    chosen = [g for g in grasps if g.side == "right"][:: max(1, len(grasps) // (2 * REFITS))][:REFITS]
    fields = {g.object_id: object_field(by_id[g.object_id]) for g in chosen}
    shapes = [model.shaped(rng.uniform(-2, 2, model.num_betas)) for _ in range(SHAPES)]
    refit_grasp(shapes[0], by_id[chosen[0].object_id], chosen[0], fields[chosen[0].object_id])   # compile kernels
    wall, cpu, ok, pen, second = [], [], 0, [], 0
    for g in chosen:
        for shaped in shapes:
            t0, c0 = time.perf_counter(), time.process_time()
            fitted = refit_grasp(shaped, by_id[g.object_id], g, fields[g.object_id])
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
            ok += fitted.ok
            second += fitted.figures["iterations"] > REFIT_ROUNDS * REFIT_NFEV
            pen.append(fitted.penetration_max_m * 1e3)
    return {"refits": len(wall), "wall_ms_median": round(1e3 * float(np.median(wall)), 1),
            "wall_ms_p90": round(1e3 * float(np.percentile(wall, 90)), 1),
            "cpu_ms_median": round(1e3 * float(np.median(cpu)), 1), "within_drop_rule": ok,
            "within_1mm": int(sum(p <= REFIT_PENETRATION * 1e3 for p in pen)), "second_pass": int(second),
            "penetration_max_mm": round(float(max(pen)), 3)}
