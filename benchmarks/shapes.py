"""The open hand's shape space: what shape costs the forward pass, and the pose correctives' error against DQS over
shapes and poses.

Correctives compared on the same held-out poses (importer's draws), each at beta = 0, beta ~ N(0, I) and each of the
first two directions at -+3:
    template_fit       the committed correctives (fitted at beta = 0, as the importer does by default)
    shape_mixed_fit    refitted over shaped hands (`fit_pose_correctives(shapes=True)`: one shape per pose)
    shape_linear_fit   an experiment, not in the model format: correctives that vary linearly with the first two
                       betas (features f and beta_k f), to measure what shape-dependent correctives would buy
"""

from __future__ import annotations

import time

import numpy as np

from darthand.model.anatomy import sample_poses
from darthand.model.dqs import dqs
from darthand.model.forward import forward, pose_feature
from darthand.template.correctives import feature_masks, fit_pose_correctives, rest_offsets, solve_correctives


def run(n_train: int = 3000, n_test: int = 300, seed: int = 0) -> dict:
    from darthand.model.load import load_model

    model = load_model("open")
    if model.num_betas == 0:
        raise SystemExit("shapes benchmark: the open hand has no shape directions")
    out = {"shape_dims": model.num_betas, "forward": forward_speed(model),
           "shape_space": {k: model.meta["shape_space"][k] for k in ("explained_variance", "residual_mm",
                                                                       "moments", "calibration")}}
    poses = sample_poses(model, n_test, np.random.default_rng([seed, 2]))
    cases = evaluation_shapes(model, n_test, seed)
    t = time.perf_counter()
    mixed, report = fit_pose_correctives(model, n_train=n_train, n_test=200, seed=seed, restrict=True, shapes=True)
    mixed_seconds = time.perf_counter() - t
    linear = shape_linear_fit(model, n_train, seed, k=2)
    out["correctives"] = {
        "template_fit": errors_over_shapes(model, poses, cases, lambda b, f: model.posedirs, "posedirs"),
        "shape_mixed_fit": errors_over_shapes(model, poses, cases, lambda b, f: mixed, "posedirs"),
        "shape_linear_fit": errors_over_shapes(model, poses, cases, linear, "offsets"),
        "shape_mixed_fit_seconds": round(mixed_seconds, 2),
        "shape_mixed_fit_ridge": report["ridge"],
    }
    return out


def forward_speed(model, batch: int = 1024, repeats: int = 5) -> dict:
    """float32 poses per second of `forward` without and with betas (best of `repeats`)."""
    rng = np.random.default_rng(0)
    pose = rng.normal(0, 0.3, (batch, 48)).astype(np.float32)
    betas = rng.standard_normal((batch, model.num_betas)).astype(np.float32)
    out = {}
    for name, b in (("no_betas", None), ("betas_per_pose", betas)):
        forward(model, pose[:8], None if b is None else b[:8], dtype=np.float32)
        best = min(_timed(lambda b=b: forward(model, pose, b, dtype=np.float32)) for _ in range(repeats))
        out[f"{name}_poses_per_s"] = round(batch / best)
    return out


def evaluation_shapes(model, n: int, seed: int) -> dict:
    """name -> betas (n, S): zero, N(0, I), and directions 1 and 2 at -+3."""
    S = model.num_betas
    cases = {"beta=0": np.zeros((n, S)), "beta~N(0,I)": np.random.default_rng([seed, 5]).standard_normal((n, S))}
    for i in range(2):
        for s in (-3.0, 3.0):
            b = np.zeros((n, S))
            b[:, i] = s
            cases[f"beta{i + 1}={s:+g}"] = b
    return cases


def errors_over_shapes(model, poses, cases: dict, correctives, kind: str) -> dict:
    """Mean and max distance (mm) to DQS of LBS and of LBS + correctives for every case of shapes.

    correctives(betas, features) gives posedirs (V, 3, 135) (kind "posedirs") or rest offsets (B, V, 3) ("offsets").
    """
    out = {}
    for name, betas in cases.items():
        target = dqs(model, poses, betas)
        lbs = forward(model, poses, betas, correctives=False)
        f = pose_feature(lbs.rotations)
        c = correctives(betas, f)
        offsets = np.einsum("vck,bk->bvc", c, f) if kind == "posedirs" else c
        blended = np.einsum("vj,bjkl->bvkl", model.weights, lbs.transforms[:, :, :3, :3])
        corrected = lbs.vertices + np.einsum("bvkl,bvl->bvk", blended, offsets)
        e_lbs = np.linalg.norm(lbs.vertices - target, axis=-1) * 1000
        e_cor = np.linalg.norm(corrected - target, axis=-1) * 1000
        out[name] = {"lbs_mean_mm": round(float(e_lbs.mean()), 4), "lbs_max_mm": round(float(e_lbs.max()), 3),
                     "corrected_mean_mm": round(float(e_cor.mean()), 4),
                     "corrected_max_mm": round(float(e_cor.max()), 3)}
    return out


def shape_linear_fit(model, n_train: int, seed: int, k: int = 2, ridge: float = 1e-5, chunk: int = 50):
    """Correctives linear in the first k betas, P0 f + sum_i beta_i P_i f, fitted to DQS over shaped hands; returns
    a function (betas, features) -> rest offsets (B, V, 3)."""
    poses = sample_poses(model, n_train, np.random.default_rng([seed, 0]))
    betas = np.random.default_rng([seed, 0, 1]).standard_normal((n_train, model.num_betas))

    def features(b, f):
        return np.concatenate([f] + [f * b[:, [i]] for i in range(k)], axis=1)

    V, K = model.num_vertices, 135 * (k + 1)
    FtF, FtO = np.zeros((K, K)), np.zeros((K, V * 3))
    for s in range(0, n_train, chunk):
        f, o = rest_offsets(model, poses[s:s + chunk], betas[s:s + chunk])
        x = features(betas[s:s + chunk], f)
        FtF += x.T @ x
        FtO += x.T @ o.reshape(len(x), -1)
    P = solve_correctives(FtF, FtO.reshape(K, V, 3), ridge, np.tile(feature_masks(model), (1, k + 1)))
    return lambda b, f: np.einsum("vck,bk->bvc", P, features(b, f))


def _timed(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t
