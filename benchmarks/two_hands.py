"""Two-hand frames (dataset/interactions.py, model/hand_pair.py): per interaction type, over FRAMES sampled frames
(a DART pose per frame, as the plan draws them): the share resolved on the first draw, redraws and fallbacks to
'apart', the penetration left (max, p99 over the vertices inside, mm) by the fit's own measure, by MeshLab's face
test and by trimesh (an independent measure: vertices inside the other hand's wrist-capped mesh by its ray test,
their depth by its exact closest point), how far the left hand moved, and CPU per frame of planning.

Writes two_hands_sheet.png into the output folder: the first two frames of each type (right hand tan, left blue),
and two_hands_interlaced.png: the first two interlaced frames seen down the fingers, from above and from the side.
FRAMES: the TWO_HANDS_FRAMES environment variable (default 4 per type); the digits are fitted too (the plan's default
--interaction-fit digits: InteractionSampler's fit_digits), their movement reported (max and mean degrees over the
fitted angles); TWO_HANDS_DIGITS=0 measures the rigid fit.
CPU is process time of one sampler call (the one-hand draws a plan makes besides, ~1.3 ms, left out), after a
warm-up draw (numba's first compilations).
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from benchmarks._common import bench_model


def run(out) -> dict:
    from darthand.dataset import poses
    from darthand.dataset.interaction_shares import TYPES
    from darthand.dataset.interactions import InteractionSampler
    from darthand.model.mirror import mirror_model

    frames = int(os.environ.get("TWO_HANDS_FRAMES", "4"))
    digits = os.environ.get("TWO_HANDS_DIGITS", "1") == "1"
    right, where = bench_model()
    left = mirror_model(right)
    dart = poses.GridSlerp(right, poses.load_reference("gestures", right))
    InteractionSampler(right, left, {"touching": 1.0}).sample(1, 0, 0.5, dart.sample(1, 0)[0], None)  # warm-up
    per, shown = {}, {}
    for kind in TYPES:
        sampler = InteractionSampler(right, left, {kind: 1.0}, fit_digits=digits)
        rows = []
        for i in range(frames):
            pose, _ = dart.sample(0, i * 7)
            t = time.process_time()
            drawn = sampler.sample(0, i, 0.5, pose, None)
            cpu = time.process_time() - t
            rows.append(_frame_figures(right, left, drawn, cpu))
            shown.setdefault(kind, []).append(drawn)
        per[kind] = _type_figures(rows)
    cpu = [per[k]["cpu_ms_mean"] for k in TYPES]
    _contact_sheet(right, left, shown, Path(out) / "two_hands_sheet.png")
    _end_views(right, left, shown["interlaced"][:2], Path(out) / "two_hands_interlaced.png")
    return {"model": where, "frames_per_type": frames, "fit_digits": digits,
            "cpu_ms_per_frame_mean": round(float(np.mean(cpu)), 1),
            "resolved_share": round(float(np.mean([per[k]["resolved_share"] for k in TYPES])), 3),
            "trimesh_inside_vertices": int(sum(per[k]["trimesh_inside_vertices"] for k in TYPES)), "types": per}


def _contact_sheet(right, left, shown: dict, path: Path, per_type: int = 2) -> None:
    """A PNG of the first frames of each type: the two posed meshes (right tan, left blue) by matplotlib."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from darthand.model import hand_pair

    fig = plt.figure(figsize=(2.4 * len(shown), 2.4 * per_type))
    for col, frames in enumerate(shown.values()):
        for row, drawn in enumerate(frames[:per_type]):
            hands = [hand_pair.pose_hand(right, drawn["right_pose"]),
                     hand_pair.pose_hand(left, drawn["left_pose"], T=np.asarray(drawn["placement"]))]
            ax = fig.add_subplot(per_type, len(shown), row * len(shown) + col + 1, projection="3d")
            for hand, colour in zip(hands, ("#d9a27a", "#7a9fd9")):
                v = hand.vertices
                ax.plot_trisurf(v[:, 0], v[:, 2], -v[:, 1], triangles=hand.faces, color=colour, linewidth=0)
            both = np.concatenate([h.vertices for h in hands])
            c, r = both.mean(0), (both.max(0) - both.min(0)).max() / 2.2
            ax.set_xlim(c[0] - r, c[0] + r)
            ax.set_ylim(c[2] - r, c[2] + r)
            ax.set_zlim(-c[1] - r, -c[1] + r)
            ax.view_init(elev=30 if row == 0 else -30, azim=-70)
            ax.set_axis_off()
            ax.set_title(f"{drawn['type']} {drawn['record']['resolved']['contact_gaps_mm'] or ''}", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def _end_views(right, left, frames: list, path: Path) -> None:
    """A PNG of interlaced frames seen down the fingers (from -X: the fingers' row across, palm to palm up), from
    above the left hand's back and from the side: whether the fingers pass between each other."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from darthand.model import hand_pair

    views = ((0, 180), (90, -90), (20, -60))
    fig = plt.figure(figsize=(3.2 * len(views), 3.2 * len(frames)))
    for row, drawn in enumerate(frames):
        hands = [hand_pair.pose_hand(right, drawn["right_pose"]),
                 hand_pair.pose_hand(left, drawn["left_pose"], T=np.asarray(drawn["placement"]))]
        both = np.concatenate([h.vertices for h in hands])
        c, r = both.mean(0), (both.max(0) - both.min(0)).max() / 2.2
        for col, (elev, azim) in enumerate(views):
            ax = fig.add_subplot(len(frames), len(views), row * len(views) + col + 1, projection="3d")
            for hand, colour in zip(hands, ("#d9a27a", "#7a9fd9")):
                v = hand.vertices
                ax.plot_trisurf(v[:, 0], v[:, 2], -v[:, 1], triangles=hand.faces, color=colour, linewidth=0)
            ax.set_xlim(c[0] - r, c[0] + r)
            ax.set_ylim(c[2] - r, c[2] + r)
            ax.set_zlim(-c[1] - r, -c[1] + r)
            ax.view_init(elev=elev, azim=azim)
            ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def _frame_figures(right, left, out, cpu: float) -> dict:
    from darthand.model import hand_pair

    a = hand_pair.pose_hand(right, out["right_pose"])
    b = hand_pair.pose_hand(left, out["left_pose"], T=np.asarray(out["placement"]))
    inside, depth = _trimesh_inside(a, b)
    rec = out["record"]
    return {"first": rec["attempts"] == 1 and "redrawn_from" not in rec, "redraws": rec["attempts"] - 1,
            "fallback": "redrawn_from" in rec, "max_mm": rec["resolved"]["max_mm"], "p99_mm": rec["resolved"]["p99_mm"],
            "meshlab_faces": rec["resolved"]["crossing_faces"], "trimesh_inside": inside, "trimesh_depth_mm": depth,
            "before_max_mm": rec["resolved"]["before_max_mm"], "turn_deg": rec["resolved"]["turn_deg"],
            "shift_mm": rec["resolved"]["shift_mm"], "cpu_ms": cpu * 1e3,
            "fit_cpu_ms": out["resolution"].cpu_s * 1e3, "gaps_mm": rec["resolved"]["contact_gaps_mm"],
            "digits_max_deg": rec["resolved"].get("digits_max_deg", 0.0),
            "digits_mean_deg": rec["resolved"].get("digits_mean_deg", 0.0)}


def _trimesh_inside(a, b) -> tuple[int, float]:
    """Vertices of either hand inside the other (trimesh's ray test) and their largest depth (mm, trimesh's exact
    closest point)."""
    import trimesh
    from trimesh.proximity import closest_point_naive

    from darthand.model.topology import close_loops

    n, deepest = 0, 0.0
    for p, q in ((a, b), (b, a)):
        mesh = trimesh.Trimesh(*close_loops(q.vertices, q.faces), process=False)
        inside = p.vertices[mesh.contains(p.vertices)]
        n += len(inside)
        if len(inside):
            deepest = max(deepest, float(closest_point_naive(mesh, inside)[1].max()) * 1e3)
    return n, round(deepest, 4)


def _type_figures(rows: list[dict]) -> dict:
    def col(k):
        return np.array([r[k] for r in rows], np.float64)

    gaps = [g for r in rows for g in r["gaps_mm"]]
    return {"frames": len(rows), "resolved_share": round(float(col("first").mean()), 3),
            "redraws": int(col("redraws").sum()), "fallbacks": int(col("fallback").sum()),
            "max_mm": float(col("max_mm").max()), "p99_mm": float(col("p99_mm").max()),
            "meshlab_failures": int((col("meshlab_faces") > 0).sum()),
            "trimesh_inside_vertices": int(col("trimesh_inside").sum()),
            "trimesh_max_depth_mm": float(col("trimesh_depth_mm").max()),
            "before_max_mm_mean": round(float(col("before_max_mm").mean()), 3),
            "turn_deg_mean": round(float(col("turn_deg").mean()), 3), "turn_deg_max": float(col("turn_deg").max()),
            "shift_mm_mean": round(float(col("shift_mm").mean()), 3),
            "digits_max_deg": float(col("digits_max_deg").max()),
            "digits_mean_deg": round(float(col("digits_mean_deg").mean()), 3),
            "contact_gap_mm_max": max(gaps) if gaps else None,
            "cpu_ms_mean": round(float(col("cpu_ms").mean()), 1), "cpu_ms_max": round(float(col("cpu_ms").max()), 1),
            "fit_cpu_ms_mean": round(float(col("fit_cpu_ms").mean()), 1)}


def summary(result: dict) -> str:
    lines = [f"Model: {result['model']}; {result['frames_per_type']} frames per type; mean CPU per two-hand frame "
             f"of planning {result['cpu_ms_per_frame_mean']} ms (goal 50 ms); digits fitted: "
             f"{result.get('fit_digits', False)}.", "",
             "| type | resolved first draw | redraws | fallbacks | max / p99 mm | MeshLab fails | trimesh inside "
             "| turn deg (mean) | shift mm (mean) | digits deg max / mean | contact gap mm (max) "
             "| CPU ms mean / max (fit) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for kind, r in result["types"].items():
        lines.append(f"| {kind} | {r['resolved_share']:.0%} | {r['redraws']} | {r['fallbacks']} | {r['max_mm']:.3g} / "
                     f"{r['p99_mm']:.3g} | {r['meshlab_failures']} | {r['trimesh_inside_vertices']} | "
                     f"{r['turn_deg_mean']} | {r['shift_mm_mean']} | {r.get('digits_max_deg', 0.0)} / "
                     f"{r.get('digits_mean_deg', 0.0)} | {r['contact_gap_mm_max']} | "
                     f"{r['cpu_ms_mean']} / {r['cpu_ms_max']} ({r['fit_cpu_ms_mean']}) |")
    return "\n".join(lines)
