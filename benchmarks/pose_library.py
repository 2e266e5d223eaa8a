"""Fitting the pose library to a model (model/library_fit): seconds per pose and per side, how many poses the fit
changed and by how much (degrees), and how many cross themselves before and after (model/self_crossing).

Headline: `right.fit_seconds` (every library pose on the right model, one process: what `make assets`' pose-library
step costs). The left model is the right one's mirror, so `make assets` fits the right side only and the left reads
that fit; `left` fits the first LEFT_POSES poses on the mirrored model to show the cost per side is the same and that
the two fits agree (largest difference in degrees). Writes the fit record and the fitted library's contact sheets
(library_<group>.png) into <out>/pose_library/.
"""

from __future__ import annotations


import numpy as np

from benchmarks._common import bench_model

LEFT_POSES = 24


def run(out) -> dict:
    from darthand.model.library_fit import fit_library, model_library, write_fit
    from darthand.model.library_sheet import library_sheets
    from darthand.model.mirror import mirror_model
    from darthand.model.pose_library import library_poses
    from darthand.model.regions import ensure_face_labels
    from darthand.model.self_crossing import SelfCrossing

    model, where = bench_model()
    model = ensure_face_labels(model)
    poses = library_poses()
    right = fit_library(model, poses)
    folder = out / "pose_library"       # not <out>/*.json: those are the benchmarks' results
    write_fit(folder / "fit_right.json", right)
    left_model = mirror_model(model)
    left = fit_library(left_model, poses[:LEFT_POSES])
    authored = _authored(model, poses)
    fitted = model_library(model, fit=folder / "fit_right.json", poses=poses)
    crossing = SelfCrossing(model)
    before = crossing.crossing_poses(authored)
    after = crossing.crossing_poses(fitted.poses)
    library_sheets(model, fitted, folder)
    return {"model": where, "poses": len(poses), "right": _side(right), "left": _side(left),
            "left_vs_right_max_deg": _agreement(left, right),
            "crossing_poses": {"authored": sum(c is not None for c in before),
                               "fitted": sum(c is not None for c in after),
                               "fitted_names": [n for n, c in zip(fitted.names, after) if c is not None]}}


def _authored(model, poses) -> np.ndarray:
    """(N, 48) the authored angles on the model (no fit)."""
    from darthand.model.anatomy import angles_to_axis_angle

    return angles_to_axis_angle(model, np.stack([p.angles for p in poses])).reshape(len(poses), -1)


def _side(record: dict) -> dict:
    """Timing and change figures of one fit record."""
    per = record["poses"].values()
    seconds = np.array([p["seconds"] for p in per])
    change = np.array([p["max_change_deg"] for p in per])
    status = [p["status"] for p in per]
    changed = change[change > 1e-3]
    return {"fit_seconds": record["seconds"], "per_pose_s": {"mean": round(float(seconds.mean()), 3),
                                                            "median": round(float(np.median(seconds)), 3),
                                                            "max": round(float(seconds.max()), 3)},
            "status": {s: status.count(s) for s in ("kept", "fitted", "unresolved")},
            "changed_poses": int(len(changed)),
            "change_deg": {"median": round(float(np.median(changed)), 2) if len(changed) else 0.0,
                           "max": round(float(changed.max()), 2) if len(changed) else 0.0},
            "unresolved": [n for n, p in record["poses"].items() if p["status"] == "unresolved"]}


def _agreement(left: dict, right: dict) -> float:
    """Largest difference (degrees) between the left and right fits of the poses both fitted."""
    from darthand.model.gestures import joints_to_angles

    diffs = [np.abs(joints_to_angles(p["joints"]) - joints_to_angles(right["poses"][n]["joints"])).max()
             for n, p in left["poses"].items()]
    return round(float(np.rad2deg(max(diffs, default=0.0))), 4)


def summary(result: dict) -> str:
    r, lf = result["right"], result["left"]
    return "\n".join([
        f"{result['poses']} library poses on {result['model']}.",
        f"- right: {r['fit_seconds']:.0f} s ({r['per_pose_s']['mean']:.2f} s a pose, max {r['per_pose_s']['max']:.1f})"
        f"; {r['status']}; {r['changed_poses']} changed, median {r['change_deg']['median']} deg, max "
        f"{r['change_deg']['max']} deg",
        f"- left (first {sum(lf['status'].values())} poses): {lf['per_pose_s']['mean']:.2f} s a pose; left vs "
        f"right fit differ by at most {result['left_vs_right_max_deg']} deg",
        f"- poses crossing themselves (model/self_crossing): {result['crossing_poses']['authored']} authored, "
        f"{result['crossing_poses']['fitted']} fitted {result['crossing_poses']['fitted_names']}"])
