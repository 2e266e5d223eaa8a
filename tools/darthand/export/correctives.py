"""The pose correctives an asset carries, and what each export option costs.

Shapes: V vertices, J = 16 joints, K exported corrective channels, S exported blend shapes (the channels encoded
with weights in [0, 1], `blendshapes.py`), B poses.

Export option `correctives` (`parse_correctives`):
    full   the model's 135 pose correctives; channel values = the pose feature f = flatten(R_i - I), channel
           `pose_<joint>_r<row><col>`
    pca:K  K directions of the SVD of the corrective matrix A = posedirs arranged (3V, 135), A = U S W^T:
           channel offsets B = U_K S_K (3V, K), values c = W_K^T f (K,), so the exported offset B c = U_K U_K^T A f is
           the best rank-K approximation of A in the Frobenius norm. It treats every pose-feature direction
           alike, although hands use few of them.
    pose-pca:K  the same with the pose-feature directions weighted by how poses use them: with
           C = E[f f^T] over POSE_PCA_SAMPLES anatomical poses (`anatomy.sample_poses`, seed POSE_PCA_SEED)
           and C = L L^T, the SVD A L = U S W^T gives offsets B = U_K (3V, K) and values c = U_K^T A f, the
           rank-K projection minimising the mean squared offset error over that pose distribution
           (about 10x smaller max error than pca:K at K = 32 on the open hand; see the export benchmark)
    none   no correctives: plain skinning of the rest template

Every channel is exported as one or two blend shapes whose weights stay in [0, 1] for every rotation (Blender and
other importers clamp shape weights there): the ranges used are exact bounds of the channel over all rotations
(the diagonal of R_i - I lies in [-2, 0], the off-diagonal entries in [-1, 1]; a PCA channel's range follows by
interval arithmetic), see `blendshapes.py`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darthand.errors import InputError
from darthand.export.blendshapes import ShapeEncoding, encode_channels, linear_ranges
from darthand.export.influences import pruned_model
from darthand.model.anatomy import sample_poses
from darthand.model.forward import forward, pose_feature
from darthand.model.hand_model import HandModel
from darthand.model.layout import JOINT_NAMES, NUM_JOINTS, NUM_POSE_FEATURES
from darthand.model.rotations import axis_angle_to_matrix

POSE_PCA_SAMPLES = 4096
POSE_PCA_SEED = 2022


@dataclass(frozen=True)
class Correctives:
    """The pose correctives an asset carries.

    offsets: (V, 3, K) float64, one channel per column (metres).
    projection: (K, 135) float64 or None; channel values = projection @ pose feature (None: the identity, the
        values ARE the pose feature, K = 135).
    mode: 'full', 'pca:K', 'pose-pca:K' or 'none'; channels: K channel names; encoding: the exported blend shapes
        (S of them, weights in [0, 1]).
    """

    mode: str
    offsets: np.ndarray
    projection: np.ndarray | None
    channels: tuple[str, ...]
    encoding: ShapeEncoding

    @property
    def count(self) -> int:
        """Number of exported blend shapes S."""
        return self.encoding.count

    @property
    def names(self) -> tuple[str, ...]:
        """The S exported blend-shape names."""
        return self.encoding.names

    def shape_offsets(self, channel_offsets: np.ndarray | None = None) -> np.ndarray:
        """(V, 3, S) offsets of the exported blend shapes (of `channel_offsets` (N, 3, K), default the hand's)."""
        return self.encoding.offsets(self.offsets if channel_offsets is None else channel_offsets)

    def values(self, rotations: np.ndarray) -> np.ndarray:
        """(B, K) signed channel values of poses with local rotations (B, 16, 3, 3)."""
        f = pose_feature(np.asarray(rotations, dtype=np.float64))
        return f if self.projection is None else f @ self.projection.T

    def weights(self, rotations: np.ndarray) -> np.ndarray:
        """(B, S) exported blend-shape weights, in [0, 1], of poses with local rotations (B, 16, 3, 3)."""
        return self.encoding.weights(self.values(rotations))

    def weights_of_poses(self, poses: np.ndarray) -> np.ndarray:
        """(B, S) exported blend-shape weights of axis-angle poses (B, 48)."""
        aa = np.asarray(poses, dtype=np.float64).reshape(-1, NUM_JOINTS, 3)
        return self.weights(axis_angle_to_matrix(aa))


def corrective_names() -> tuple[str, ...]:
    """The 135 pose-corrective channel names `pose_<joint>_r<row><col>`: joint 1..15, entry (r, c) of R_j - I."""
    return tuple(f"pose_{JOINT_NAMES[j]}_r{r}{c}" for j in range(1, NUM_JOINTS) for r in range(3) for c in range(3))


def pose_feature_ranges() -> tuple[np.ndarray, np.ndarray]:
    """(135,), (135,) exact bounds of the pose feature over all rotations: diagonal entries of R - I in [-2, 0],
    off-diagonal ones in [-1, 1]."""
    diag = np.tile(np.eye(3).reshape(-1) > 0, NUM_JOINTS - 1)
    return np.where(diag, -2.0, -1.0), np.where(diag, 0.0, 1.0)


def parse_correctives(text: str) -> tuple[str, int | None]:
    """'full' -> ('full', None), 'none' -> ('none', None), 'pca:K' -> ('pca', K), 'pose-pca:K' -> ('pose-pca', K)."""
    text = str(text)
    if text in ("full", "none"):
        return text, None
    kind, _, k = text.partition(":")
    if kind in ("pca", "pose-pca") and k.isdigit() and 1 <= int(k) <= NUM_POSE_FEATURES:
        return kind, int(k)
    raise InputError(f"--correctives: {text!r} is not 'full', 'none', 'pca:K' or 'pose-pca:K' with K in "
                     f"1..{NUM_POSE_FEATURES}")


def export_correctives(model: HandModel, mode: str = "full") -> Correctives:
    """The correctives to export for `mode` ('full' | 'pca:K' | 'pose-pca:K' | 'none'); see the module docstring."""
    kind, k = parse_correctives(mode)
    V = model.num_vertices
    lo, hi = pose_feature_ranges()
    if kind == "full":
        names = corrective_names()
        return Correctives("full", model.posedirs, None, names, encode_channels(names, lo, hi))
    if kind == "none":
        return Correctives("none", np.zeros((V, 3, 0)), np.zeros((0, NUM_POSE_FEATURES)), (),
                           encode_channels((), [], []))
    assert k is not None, "parse_correctives gives a count with pca:K and pose-pca:K"
    A = model.posedirs.reshape(3 * V, NUM_POSE_FEATURES)
    names = tuple(f"pose_pca{i:03d}" for i in range(k))
    if kind == "pca":
        U, S, Wt = np.linalg.svd(A, full_matrices=False)
        offsets, projection = (U[:, :k] * S[:k]).reshape(V, 3, k), Wt[:k].copy()
    else:
        U = np.linalg.svd(A @ pose_feature_sqrt_covariance(model), full_matrices=False)[0][:, :k]
        offsets, projection = U.reshape(V, 3, k), U.T @ A
    return Correctives(f"{kind}:{k}", offsets, projection, names,
                       encode_channels(names, *linear_ranges(projection, lo, hi)))


def pose_feature_sqrt_covariance(model: HandModel) -> np.ndarray:
    """(135, 135) L with L L^T = E[f f^T], the second moment of the pose feature over POSE_PCA_SAMPLES anatomical
    poses of `model` (seeded, so the export is deterministic); a tiny ridge keeps the Cholesky factor defined."""
    poses = sample_poses(model, POSE_PCA_SAMPLES, np.random.default_rng(POSE_PCA_SEED))
    f = pose_feature(axis_angle_to_matrix(poses.reshape(-1, NUM_JOINTS, 3)))
    C = f.T @ f / len(f)
    return np.linalg.cholesky(C + 1e-12 * np.trace(C) * np.eye(NUM_POSE_FEATURES))


def exported_model(model: HandModel, correctives: Correctives, influences: int | None = None) -> HandModel:
    """The rig an exported asset carries: `model` with its correctives replaced by the exported ones (offsets @
    projection, (V, 3, 135)) and its skin weights pruned to `influences`. `forward` on it is what a consumer of
    the asset computes, so comparing it with `forward` on `model` measures the export options' error."""
    if correctives.projection is None:
        posedirs = correctives.offsets
    elif correctives.count == 0:
        posedirs = np.zeros_like(model.posedirs)
    else:
        posedirs = correctives.offsets @ correctives.projection
    return pruned_model(model.replace(posedirs=posedirs), influences)



# ------------------------------------------------------------------------------------------------ option errors


def corrective_error(model: HandModel, correctives: Correctives, poses: np.ndarray) -> np.ndarray:
    """(B,) max over vertices of |exported corrective offset - model's corrective offset| (metres) for poses (B, 48).

    Skinning is linear in the rest-frame offset and rigid per joint, so this bounds the posed-vertex error the
    corrective approximation alone adds (skinning weights that sum to 1 do not lengthen an offset); `option_errors`
    measures the posed error itself.
    """
    rot = axis_angle_to_matrix(np.asarray(poses, dtype=np.float64).reshape(-1, NUM_JOINTS, 3))
    f = pose_feature(rot)
    V = model.num_vertices
    exact = f @ model.posedirs.reshape(3 * V, -1).T
    approx = correctives.values(rot) @ correctives.offsets.reshape(3 * V, -1).T if correctives.count else 0.0
    diff = (exact - approx).reshape(len(f), V, 3)
    return np.linalg.norm(diff, axis=2).max(axis=1)


def rig_error(model: HandModel, rig: HandModel, poses: np.ndarray, truth: np.ndarray | None = None) -> float:
    """Max vertex distance (metres) between `forward` on `model` (or its precomputed vertices `truth` (B, V, 3))
    and `forward` on `rig` over poses (B, 48); 0 for no poses."""
    if not len(poses):
        return 0.0
    truth = forward(model, poses).vertices if truth is None else truth
    return float(np.linalg.norm(forward(rig, poses).vertices - truth, axis=-1).max())


def option_errors(model: HandModel, correctives: Correctives, influences: int | None, poses: np.ndarray,
                  truth: np.ndarray | None = None) -> dict:
    """What each export option costs over poses (B, 48), as posed max vertex errors (metres) against the model:
    `influence_error_m` of the pruned skin weights (with the model's correctives), `corrective_error_m` of the
    exported correctives (with the full weights)."""
    if len(poses) and truth is None:
        truth = forward(model, poses).vertices
    return {"influence_error_m": rig_error(model, pruned_model(model, influences), poses, truth),
            "corrective_error_m": rig_error(model, exported_model(model, correctives), poses, truth)}



def channel_offsets(posedirs: np.ndarray | None, correctives: Correctives, count: int) -> np.ndarray:
    """(N, 3, K) channel offsets of another surface skinned with the hand (a glove, the forearm cap) whose own
    correctives are `posedirs` (N, 3, 135) or None, driven by the hand's channel values c = P f
    (`Correctives.shape_offsets` turns them into the exported blend shapes); `count` = N.

    G = posedirs is mapped through the pseudo-inverse of the projection, D = G P^+ (G itself for full, G W_K^T for
    pca:K whose P = W_K has orthonormal rows; the least-squares fit for pose-pca:K), so D c = G P^+ P f is G f
    restricted to the pose directions the hand's channels carry. (N, 3, 0) without correctives.
    """
    if posedirs is None or not len(correctives.channels):
        return np.zeros((count, 3, 0))
    if correctives.projection is None:
        return posedirs
    return posedirs @ np.linalg.pinv(correctives.projection)
