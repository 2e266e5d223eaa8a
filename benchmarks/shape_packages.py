"""Shapes in packages: what the shape dials cost (file size, export time) and what dialling a shape instead of
building it costs in accuracy (the joints stay the built shape's: export/shape_dials.py).

On the open hand (wrist-enhanced, the pipeline's build/model/right.npz without textures), over the named gestures:
    dial_error        per shape direction at delta beta = +-3 (and +-1, a typical person), the max vertex distance
                      between the dialled package (UsdSkel/glTF maths: blend shapes before skinning, built joints)
                      and the rig of that shape (joints regressed from the shaped surface), plus the joints'
                      own displacement at rest
    glb               .glb size and export time without and with the dials (4 influences, full correctives)
    usd               payload.usdc size without and with the dials
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path



def run() -> dict:
    from darthand.export.gestures import gesture_poses
    from darthand.export.gltf_export import GltfOptions, export_gltf
    from darthand.export.shape_dials import ShapeDials, dial_error, shape_dials
    from darthand.export.usd_asset import ExportOptions, export_usd
    from darthand.model.load import load_model
    from darthand.model.wrist import add_wrist

    model = add_wrist(load_model("open"))
    names, poses = gesture_poses(model)
    out = {"model": {"vertices": model.num_vertices, "shape_dims": model.num_betas}, "gestures": len(names)}
    dials = shape_dials(model)
    out["dial_error_at_3"] = _mm(dial_error(model, dials, poses))
    one = ShapeDials(dials.offsets, dials.encoding, dials.baked, 1.0)
    out["dial_error_at_1"] = _mm(dial_error(model, one, poses))
    with tempfile.TemporaryDirectory() as tmp:
        glb = {}
        for label, r in (("without_dials", 0.0), ("with_dials", 3.0)):
            path = Path(tmp) / f"{label}.glb"
            t = time.perf_counter()
            export_gltf(model, path, options=GltfOptions(shape_dials=r), gestures=(names, poses))
            glb[label] = {"mb": round(path.stat().st_size / 1e6, 3), "seconds": round(time.perf_counter() - t, 2)}
        out["glb"] = glb
        usd = {}
        for label, r in (("without_dials", 0.0), ("with_dials", 3.0)):
            info = export_usd(model, Path(tmp) / label, options=ExportOptions(shape_dials=r), gestures=(names, poses))
            usd[label] = {"payload_mb": round(info["files"]["payload.usdc"] / 1e6, 3),
                          "seconds": info["write_seconds"]}
        out["usd"] = usd
    return out


def _mm(record: dict) -> dict:
    return {"max_vertex_error_mm": round(1000 * record["max_vertex_error_m"], 3),
            "per_direction_mm": [round(1000 * x, 3) for x in record["per_direction_m"]],
            "max_joint_shift_mm": round(1000 * record["max_joint_shift_m"], 3), "poses": record["poses"]}


def summary(res: dict) -> str:
    e3, e1 = res["dial_error_at_3"], res["dial_error_at_1"]
    g, u = res["glb"], res["usd"]
    return "\n".join([
        f"Dialling a shape instead of building it (joints stay put), worst over {res['gestures']} gestures: "
        f"**{e3['max_vertex_error_mm']:.2f} mm at |delta beta| = 3**, {e1['max_vertex_error_mm']:.2f} mm at 1 "
        f"(joints move up to {e3['max_joint_shift_mm']:.2f} mm at 3).",
        "",
        f"Per direction at 3 (mm): {', '.join(f'{x:.2f}' for x in e3['per_direction_mm'])}.",
        "",
        f"Size of the dials: .glb {g['without_dials']['mb']} -> {g['with_dials']['mb']} MB; USD payload "
        f"{u['without_dials']['payload_mb']} -> {u['with_dials']['payload_mb']} MB.",
    ])
