"""Fitting the named gestures to a model (model/gesture_fit): seconds per gesture, and what the fit changes --
faces where digits pass through each other and contact distances, authored angles against fitted.

Headline: `fit_seconds` (all gestures, one model, one process). Figures per gesture: fit seconds, status, largest
angle change (degrees), crossing digit faces and intended contact distances (mm, negative = passing through)
before and after. The model is the one `make assets` built (its face labels decide the thumb's frames), refitted.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks._common import bench_model


def run() -> dict:
    from darthand.model.anatomy import joint_frames
    from darthand.model.gesture_fit import fit_gesture
    from darthand.model.intersections import face_parts
    from darthand.model.poses import gesture_angles, gesture_contacts, list_gestures
    from darthand.model.proximity import PartSurfaces
    from darthand.model.regions import ensure_face_labels
    from darthand.template.gesture_checks import pose_checks

    model, where = bench_model()
    model = ensure_face_labels(model)
    t0 = time.perf_counter()
    surfaces, frames, parts = PartSurfaces(model), joint_frames(model), face_parts(model)
    setup = time.perf_counter() - t0
    names = list_gestures()
    fits, seconds = [], {}
    for name in names:
        t = time.perf_counter()
        fits.append(fit_gesture(model, surfaces, frames, name, gesture_angles(name), gesture_contacts(name), parts))
        seconds[name] = time.perf_counter() - t
    contacts = [gesture_contacts(n) for n in names]
    from darthand.model.anatomy import angles_to_axis_angle

    def checks(angles):
        poses = angles_to_axis_angle(model, np.stack(angles), frames).reshape(len(names), -1)
        return pose_checks(model, poses, names, contacts, surfaces)[2]

    before = checks([gesture_angles(n) for n in names])
    after = checks([f.angles for f in fits])
    per = {}
    for name, fit in zip(names, fits):
        per[name] = {"fit_s": round(seconds[name], 3), "status": fit.status,
                     "max_change_deg": round(max(map(abs, fit.changed.values()), default=0.0), 2),
                     "crossing_faces": [before[name]["between_fingers_faces"], after[name]["between_fingers_faces"]],
                     "contacts_mm": {k: [before[name]["contacts"][k], v] for k, v in after[name]["contacts"].items()}}
    return {"fit_seconds": round(setup + sum(seconds.values()), 2), "model": where,
            "vertices": model.num_vertices, "setup_s": round(setup, 3), "gestures": per}
