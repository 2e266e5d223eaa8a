"""Accessories refitted per hand shape (accessories/reshape.py): how long refitting all 50 takes (the per-frame cost
in a dataset that draws a shape per frame) and how far the tracked bores are from cutting the shaped hand afresh.

The catalogue's 50 items are generated on the open hand (fit at the catalogue's place, no placement sweep), then:
    refit_ms          one refit of all 50 for a shape (rigid items and gloves), mean and max over `shapes` shapes,
                      after the one-off `prepare_s` (tracking the sections)
    bore_error_mm     |tracked bore - bore of fit.py's fresh cut of the shaped hand at the same place| over the
                      rigid items and `error_shapes` shapes ~ N(0, I) clipped at 3: max and mean, per type
    bore_change_mm    how much the shapes change the bores (the size the refit follows), for scale
"""

from __future__ import annotations

import time

import numpy as np


def run(shapes: int = 20, error_shapes: int = 8, seed: int = 0) -> dict:
    from darthand.accessories import catalog as cat
    from darthand.accessories.fit import finger_frame, fit_ring, fit_wrist, wrist_axis
    from darthand.accessories.item import generate
    from darthand.accessories.loader import Accessory
    from darthand.accessories.reshape import ShapeRefitter
    from darthand.accessories.shape_sweep import sample_shapes
    from darthand.model.load import load_model
    from darthand.model.wrist import add_wrist

    hand = add_wrist(load_model("open"))
    spec = cat.load_spec()
    items = []
    for e in cat.entries(spec):
        b = generate(hand, e, int(spec["seed"]))
        skin = b.mesh.skin or {}
        items.append(Accessory(id=b.id, vertices=b.world_vertices, faces=b.mesh.faces,
                               parent_joint=None if b.fit is None else b.fit.joint, weights=skin.get("weights"),
                               posedirs=skin.get("posedirs"), shapedirs=skin.get("shapedirs"),
                               rest_transform=None if b.fit is None else b.rest, kind=e["type"]))
    t = time.perf_counter()
    refitter = ShapeRefitter(hand, items).prepare()
    prepare = time.perf_counter() - t
    betas = sample_shapes(hand, shapes + 1, seed)[1:]
    ms = []
    for b in betas:
        t = time.perf_counter()
        refitter.refit(b)
        ms.append(1000 * (time.perf_counter() - t))
    errors: dict = {}
    changes: dict = {}
    for b in sample_shapes(hand, error_shapes + 1, seed + 1)[1:]:
        shaped = hand.shaped(b)
        j0, axis = wrist_axis(shaped)
        for acc_id, key in refitter.keys.items():
            sec = refitter.section(acc_id)
            frame, bore = refitter.fit_of(acc_id, b)
            kind = next(a.kind for a in items if a.id == acc_id)
            if sec.kind == "ring":
                start, end = (finger_frame(shaped, sec.finger, x)[:3, 3] for x in (0.0, 1.0))
                tt = float((frame[:3, 3] - start) @ (end - start) / np.sum((end - start) ** 2))
                fresh = (fit_ring(shaped, sec.finger, key[4], 0.0, tt).bore["inner_radius"],)
            else:
                f = fit_wrist(shaped, float((frame[:3, 3] - j0) @ axis), key[4], 0.0).bore
                fresh = (f["inner_a"], f["inner_b"])
            errors.setdefault(kind, []).extend(1000 * abs(np.subtract(bore, fresh)))
            changes.setdefault(kind, []).extend(1000 * abs(np.subtract(bore, sec.bore0)))
    return {"items": len(items), "rigid": len(refitter.keys), "sections": len(refitter._sections),
            "prepare_s": round(prepare, 3),
            "refit_ms": {"mean": round(float(np.mean(ms)), 2), "max": round(float(np.max(ms)), 2), "shapes": shapes},
            "bore_error_mm": {k: {"max": round(float(np.max(v)), 4), "mean": round(float(np.mean(v)), 4)}
                              for k, v in errors.items()},
            "bore_change_mm": {k: {"max": round(float(np.max(v)), 3), "mean": round(float(np.mean(v)), 3)}
                               for k, v in changes.items()},
            "error_shapes": error_shapes}


def summary(res: dict) -> str:
    err = res["bore_error_mm"]
    worst = max(v["max"] for v in err.values())
    return "\n".join([
        f"Refitting all {res['items']} accessories to a new hand shape: **{res['refit_ms']['mean']:.0f} ms** "
        f"(max {res['refit_ms']['max']:.0f} ms over {res['refit_ms']['shapes']} shapes; {res['prepare_s']:.1f} s "
        "once per catalogue to track the sections).",
        "",
        f"Tracked bores against a fresh cut of the shaped hand, {res['error_shapes']} shapes: worst "
        f"{worst:.2f} mm; " + ", ".join(f"{k} max {v['max']:.2f} / mean {v['mean']:.2f} mm" for k, v in err.items())
        + "; the shapes change the bores by up to " + ", ".join(f"{k} {v['max']:.1f} mm"
                                                             for k, v in res["bore_change_mm"].items()) + ".",
    ])
