"""Pose-corrective fit on the open hand template: held-out error of LBS and LBS + correctives against DQS (mm),
the chosen ridge and the fit time (s) at the importer's default sample counts, with each vertex restricted to the
features that can move it (the default) and unrestricted."""

from __future__ import annotations

import time

from darthand.template.correctives import fit_pose_correctives


def run(n_train: int = 3000, n_test: int = 500, seed: int = 0) -> dict:
    from darthand.model.load import TEMPLATE_DIR, load_model

    if not (TEMPLATE_DIR / "open_right.npz").is_file():
        raise SystemExit("correctives benchmark: no open hand template (assets_src/template/open_right.npz)")
    model = load_model("open")
    out = {"vertices": model.num_vertices}
    for name, restrict in (("restricted", True), ("unrestricted", False)):
        t = time.perf_counter()
        posedirs, report = fit_pose_correctives(model, n_train=n_train, n_test=n_test, seed=seed, restrict=restrict)
        report["total_seconds"] = round(time.perf_counter() - t, 3)
        report["nonzero_fraction"] = round(float((posedirs != 0).mean()), 4)
        out[name] = report
    return out
