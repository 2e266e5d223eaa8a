"""Benchmark of the objects stage: the whole catalogue's build time (generate or import, check, write; the contact
sheet apart) and each object's, per kind, with the triangle counts. Seconds, single process."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from darthand.objects import catalog as cat
from darthand.objects.build import build_objects, build_one


def run() -> dict:
    spec = cat.load_spec()
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        catalog = build_objects(spec, Path(tmp) / "all", cat.DEFAULT_SPEC.parent, sheet=True)
        total = time.perf_counter() - t0
        per_item = {}
        for item in spec["items"]:
            t0 = time.perf_counter()
            build_one((spec, item, str(cat.DEFAULT_SPEC.parent), tmp, "spec", 0))
            per_item[item["id"]] = (item["kind"], time.perf_counter() - t0)
    per_kind: dict = {}
    for kind, seconds in per_item.values():
        per_kind.setdefault(kind, []).append(seconds)
    slowest = max(per_item, key=lambda i: per_item[i][1])
    return {"objects": len(catalog["objects"]), "skipped": len(catalog["skipped"]),
            "build_with_sheet_s": round(total, 3),
            "objects_without_sheet_s": round(sum(s for _, s in per_item.values()), 3),
            "per_object_mean_ms": round(1000 * sum(s for _, s in per_item.values()) / len(per_item), 2),
            "slowest": {"id": slowest, "ms": round(1000 * per_item[slowest][1], 2)},
            "per_kind_mean_ms": {k: round(1000 * sum(v) / len(v), 2) for k, v in sorted(per_kind.items())},
            "triangles_total": int(sum(o["triangles"] for o in catalog["objects"]))}
