"""Pose-corrective blendshapes fitted so that LBS plus correctives reproduces dual-quaternion skinning.

MANO's correctives are a linear map from the pose feature f = flatten(R_i - I), i = 1..15 (135 values), to rest-pose
vertex offsets: v_rest = v_template + P f. A template without learned correctives gets P by least squares against a
volume-preserving target, DQS of the same weights (`model.dqs`), over a few thousand anatomical poses
(`model.anatomy.sample_poses`). That removes LBS's candy-wrapper collapse at twisted and strongly bent joints.

Solving in the rest frame. Per vertex and pose s, LBS is affine in the rest position: LBS(v + o) = LBS(v) + M_s o,
with M_s = sum_j w_j R_j the blended linear part. So the rest offset that makes LBS hit DQS exactly is
o_s = M_s^-1 (DQS_s - LBS_s), and P solves min sum_s |o_s - P f_s|^2 (+ ridge |P|^2) for every vertex at once: the
normal matrix F^T F (135 x 135) is shared, only the right-hand sides F^T O differ. Both are accumulated over chunks
of poses, so memory does not grow with the number of samples. (Minimising the rest-frame residual equals minimising
the posed one when M_s is a rotation; where it is not, near a collapsed joint, it weights those poses more.)

Optionally each vertex uses only the features that can change its target (`restrict=True`, see `feature_masks`):
the local rotations on the tree paths between its weighted joints. Features outside that set are pure noise for
the vertex, and a fit that lets it use them picks up spurious responses (on the open hand, a thumb-base vertex
weighted to the wrist and the thumb MCP moved 3 cm under a thumb IP bend). Vertices with the same set share one
smaller solve.
"""

from __future__ import annotations

import time

import numpy as np

from darthand.model.anatomy import sample_poses
from darthand.model.dqs import dqs
from darthand.model.forward import forward, pose_feature
from darthand.model.hand_model import HandModel
from darthand.model.layout import NUM_JOINTS, NUM_POSE_FEATURES

RIDGE_GRID = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1)  # relative to the mean diagonal of F^T F


def fit_pose_correctives(model: HandModel, n_train: int = 3000, n_test: int = 500, seed: int = 0,
                         ridge: float | None = None, *, restrict: bool | None = True, min_weight: float = 1e-3,
                         n_val: int | None = None, sampler=None, shapes: bool = False,
                         chunk: int = 50) -> tuple[np.ndarray, dict]:
    """Fit pose-corrective blendshapes (V, 3, 135) to DQS; return them with a report of held-out errors.

    n_train, n_val, n_test: numbers of sampled poses for the fit, for choosing the ridge (and the restriction) and
        for the reported errors; three disjoint draws (n_val defaults to n_test).
    seed: seeds the numpy Generators of the three draws (seed, 0), (seed, 1), (seed, 2).
    ridge: Tikhonov weight relative to the mean diagonal of F^T F; None picks the best of RIDGE_GRID on the
        validation poses.
    restrict: limit each vertex to the features that can change its target (see the module docstring; the
        default); False lets every vertex use all 135; None tries both on the validation poses and keeps the
        better (on the open hand the unrestricted fit is ~2% lower in mean but responds to joints that cannot
        move the vertex, which poses outside the sampled ranges amplify).
    sampler: callable (model, n, rng) -> (n, 48) axis-angle poses; default `anatomy.sample_poses`.
    shapes: give every sampled pose its own shape, betas ~ N(0, I) over all of the model's shape directions (drawn
        from Generators (seed, k, 1)), so that one set of correctives serves every shape (MANO's correctives are
        shape-independent too); the report then also holds the errors of the held-out poses at beta = 0.

    The report (JSON-serialisable) holds, in millimetres over all held-out poses and vertices, the mean and max
    distance to DQS of plain LBS (`lbs_mean_mm`, `lbs_max_mm`) and of LBS + the fitted correctives
    (`corrected_mean_mm`, `corrected_max_mm`), the chosen ridge and restriction, and the fit time.
    """
    t0 = time.perf_counter()
    sampler = sample_poses if sampler is None else sampler
    n_val = n_test if n_val is None else n_val
    sizes = (n_train, n_val, n_test)
    draw = [sampler(model, n, np.random.default_rng([seed, k])) for k, n in enumerate(sizes)]
    train, val, test = (np.asarray(p, dtype=np.float64).reshape(-1, 3 * NUM_JOINTS) for p in draw)
    b_train, b_val, b_test = (shape_draw(model, n, [seed, k, 1]) if shapes else None for k, n in enumerate(sizes))

    FtF, FtO = normal_equations(model, train, chunk, b_train)
    masks = feature_masks(model, min_weight)
    val_targets = dqs(model, val, b_val)
    validation, best = {}, None
    for r in (False, True) if restrict is None else (restrict,):
        for lam in RIDGE_GRID if ridge is None else (ridge,):
            P = solve_correctives(FtF, FtO, lam, masks if r else None)
            err = held_out_errors(model, P, val, chunk, val_targets, b_val)["corrected_mean_mm"]
            validation[f"restrict={r},ridge={lam:g}"] = err
            if best is None or err < best[0]:
                best = (err, r, lam, P)
    assert best is not None, "no corrective fit was tried"
    _, best_restrict, best_ridge, posedirs = best
    fit_seconds = time.perf_counter() - t0

    errors = held_out_errors(model, posedirs, test, chunk, betas=b_test)
    report = dict(errors, n_train=len(train), n_val=len(val), n_test=len(test), seed=seed, ridge=best_ridge,
                  restrict=best_restrict, min_weight=min_weight, fit_seconds=round(fit_seconds, 3),
                  validation_corrected_mean_mm=validation, shapes=bool(shapes))
    if shapes:
        report["template_shape"] = held_out_errors(model, posedirs, test, chunk)
    return posedirs, report


def shape_draw(model: HandModel, n: int, seed) -> np.ndarray | None:
    """(n, S) betas ~ N(0, I) over the model's S shape directions (None for a model without any)."""
    if model.num_betas == 0:
        return None
    return np.random.default_rng(seed).standard_normal((n, model.num_betas))


def normal_equations(model: HandModel, poses: np.ndarray, chunk: int = 50,
                     betas: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """F^T F (135, 135) and F^T O (135, V, 3) over `poses` (N, 48) (of shapes `betas` (N, S) when given):
    features F (N, 135), rest-frame offsets O (N, V, 3) that take plain LBS onto DQS."""
    V = model.num_vertices
    FtF = np.zeros((NUM_POSE_FEATURES, NUM_POSE_FEATURES))
    FtO = np.zeros((NUM_POSE_FEATURES, V * 3))
    for s in range(0, len(poses), chunk):
        f, offsets = rest_offsets(model, poses[s:s + chunk], _rows(betas, s, chunk))
        FtF += f.T @ f
        FtO += f.T @ offsets.reshape(len(f), V * 3)
    return FtF, FtO.reshape(NUM_POSE_FEATURES, V, 3)


def rest_offsets(model: HandModel, poses: np.ndarray,
                 betas: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Pose features (B, 135) and rest-frame offsets (B, V, 3) o = M^-1 (DQS - LBS) of poses (B, 48), of shapes
    betas (B, S) when given."""
    lbs = forward(model, poses, betas, correctives=False)
    target = dqs(model, poses, betas)
    M = blended_linear_parts(model, lbs.transforms)                          # (B, V, 3, 3)
    offsets = np.linalg.solve(M, (target - lbs.vertices)[..., None])[..., 0]
    return pose_feature(lbs.rotations), offsets


def blended_linear_parts(model: HandModel, transforms: np.ndarray) -> np.ndarray:
    """(B, V, 3, 3) per-vertex LBS blend sum_j w_vj R_j of the transforms' rotation parts (B, 16, 4, 4)."""
    return np.einsum("vj,bjkl->bvkl", model.weights, transforms[:, :, :3, :3])


def feature_masks(model: HandModel, min_weight: float = 1e-3) -> np.ndarray:
    """(V, 135) bool: the features that can change vertex v's DQS - LBS difference.

    Both skinnings commute with a rigid motion applied to every joint, so o = M^-1 (DQS - LBS) depends only on the
    transforms of v's weighted joints (w_vj > min_weight) relative to each other, i.e. on the local rotations of
    the joints on the tree paths from each weighted joint up to their lowest common ancestor (that ancestor's own
    rotation, and every joint below or beside the paths, moves them all alike or not at all).
    """
    weighted = model.weights > min_weight
    sets, inverse = np.unique(weighted, axis=0, return_inverse=True)
    use = np.zeros((len(sets), NUM_JOINTS), dtype=bool)
    for k, joints in enumerate(sets):
        use[k, _path_joints(np.flatnonzero(joints), model.parents)] = True
    return np.repeat(use[inverse.reshape(-1), 1:], 9, axis=1)


def _path_joints(joints: np.ndarray, parents: np.ndarray) -> list[int]:
    """Joints on the paths from each of `joints` up to their lowest common ancestor (excluded)."""
    if len(joints) < 2:
        return []
    chains = [_ancestors(j, parents) for j in joints]      # each from the joint up to the root
    common = set(chains[0]).intersection(*chains[1:])
    lca = next(a for a in chains[0] if a in common)
    return sorted({a for chain in chains for a in chain[:chain.index(lca)]})


def _ancestors(j: int, parents: np.ndarray) -> list[int]:
    chain = [int(j)]
    while parents[chain[-1]] >= 0:
        chain.append(int(parents[chain[-1]]))
    return chain


def solve_correctives(FtF: np.ndarray, FtO: np.ndarray, ridge: float, masks: np.ndarray | None = None) -> np.ndarray:
    """(V, 3, 135) correctives P from the normal equations (F^T F + lam I) P^T = F^T O, lam = ridge * mean diag.

    masks (V, 135): per-vertex feature subsets; vertices with equal masks are solved together.
    """
    K, V = FtF.shape[0], FtO.shape[1]
    lam = ridge * np.trace(FtF) / K
    A = FtF + lam * np.eye(K)
    rhs = FtO.reshape(K, V * 3)
    P = np.zeros((K, V, 3))
    if masks is None:
        P[:] = np.linalg.solve(A, rhs).reshape(K, V, 3)
    else:
        groups, inverse = np.unique(masks, axis=0, return_inverse=True)
        for g, mask in enumerate(groups):
            verts = np.flatnonzero(inverse.reshape(-1) == g)
            idx = np.flatnonzero(mask)
            if idx.size:
                P[np.ix_(idx, verts)] = np.linalg.solve(A[np.ix_(idx, idx)], FtO[np.ix_(idx, verts)].reshape(
                    idx.size, -1)).reshape(idx.size, verts.size, 3)
    return np.ascontiguousarray(P.transpose(1, 2, 0))


def held_out_errors(model: HandModel, posedirs: np.ndarray, poses: np.ndarray, chunk: int = 50,
                    targets: np.ndarray | None = None, betas: np.ndarray | None = None) -> dict:
    """Mean and max vertex distance (mm) to DQS of plain LBS and of LBS with `posedirs`, over poses (N, 48) (of
    shapes betas (N, S) when given).

    targets: DQS vertices (N, V, 3) of the poses if already computed.
    """
    corrected_model = model.replace(posedirs=posedirs)
    sums = {"lbs": 0.0, "corrected": 0.0}
    maxes = {"lbs": 0.0, "corrected": 0.0}
    count = 0
    for s in range(0, len(poses), chunk):
        p, b = poses[s:s + chunk], _rows(betas, s, chunk)
        target = dqs(model, p, b) if targets is None else targets[s:s + chunk]
        for name, m, corr in (("lbs", model, False), ("corrected", corrected_model, True)):
            d = np.linalg.norm(forward(m, p, b, correctives=corr).vertices - target, axis=-1)
            sums[name] += float(d.sum())
            maxes[name] = max(maxes[name], float(d.max()))
        count += d.size
    return {f"{k}_{stat}_mm": round(1e3 * v, 6) for k in ("lbs", "corrected")
            for stat, v in (("mean", sums[k] / count), ("max", maxes[k]))}


def _rows(betas: np.ndarray | None, start: int, chunk: int) -> np.ndarray | None:
    return None if betas is None else betas[start:start + chunk]
