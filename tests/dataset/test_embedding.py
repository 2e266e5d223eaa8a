"""t-SNE of the dataset report (dataset/embedding.py) against its definition: the rows' perplexity, the gradient
of KL(P || Q) by finite differences, clusters kept apart, the same picture on every run."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from darthand.dataset.embedding import conditional_affinities, joint_affinities, kl_gradient, tsne
from darthand.dataset.report import pose_distances, pose_embedding


def test_each_row_has_the_perplexity_asked():
    x = np.random.default_rng(0).normal(size=(120, 6)) * np.r_[5, 1, 1, 0.2, 0.2, 0.2]
    d2 = ((x[:, None] - x[None]) ** 2).sum(-1)
    for perplexity in (5.0, 30.0):
        cond = conditional_affinities(d2, perplexity)
        assert np.allclose(cond.sum(1), 1) and not np.diag(cond).any()
        entropy = -(cond * np.log(np.where(cond > 0, cond, 1))).sum(1)
        assert np.abs(np.exp(entropy) - perplexity).max() < 1e-3 * perplexity
    p = joint_affinities(d2, 30.0)
    assert np.allclose(p, p.T) and abs(p.sum() - 1) < 1e-6


def test_gradient_is_that_of_the_kl_divergence():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(7, 3))
    p = joint_affinities(((x[:, None] - x[None]) ** 2).sum(-1), 2.0)
    y = rng.normal(size=(7, 2))

    def kl(y):
        w = 1 / (1 + ((y[:, None] - y[None]) ** 2).sum(-1))
        np.fill_diagonal(w, 0)
        q = w / w.sum()
        off = ~np.eye(7, dtype=bool)
        return (p[off] * np.log(p[off] / q[off])).sum()

    numeric = np.zeros_like(y)
    for i in np.ndindex(y.shape):
        e = np.zeros_like(y)
        e[i] = 1e-6
        numeric[i] = (kl(y + e) - kl(y - e)) / 2e-6
    assert np.allclose(kl_gradient(p, y), numeric, atol=1e-6)


def test_pose_clusters_stay_apart_and_the_picture_is_deterministic():
    """Three families of finger poses (5 degrees of noise around three poses far apart): in the embedding every
    pose's nearest neighbour is of its own family, and the families' centres are far apart against their spread."""
    rng = np.random.default_rng(2)
    centres = Rotation.from_rotvec(rng.normal(size=(3 * 15, 3)) * 0.8)
    poses = []
    for c in range(3):
        noise = Rotation.from_rotvec(rng.normal(size=(40 * 15, 3)) * np.radians(5) / np.sqrt(3))
        rot = Rotation.concatenate([centres[c * 15 + j] * noise[k * 15 + j] for k in range(40) for j in range(15)])
        poses.append(rot.as_quat()[:, [3, 0, 1, 2]].reshape(40, 15, 4))
    poses = np.concatenate(poses)
    family = np.repeat(np.arange(3), 40)
    d = pose_distances(poses, poses)
    assert np.allclose(np.diag(d), 0, atol=1e-4) and np.allclose(d, d.T)
    a = pose_embedding(poses[::2], poses[1::2])
    b = pose_embedding(poses[::2], poses[1::2])
    assert np.array_equal(a["dataset"], b["dataset"]) and np.array_equal(a["reference"], b["reference"])
    y = np.empty((120, 2))
    y[::2], y[1::2] = a["dataset"], a["reference"]
    dy = np.linalg.norm(y[:, None] - y[None], axis=-1)
    np.fill_diagonal(dy, np.inf)
    assert (family[dy.argmin(1)] == family).all()
    means = np.array([y[family == f].mean(0) for f in range(3)])
    spread = max(np.linalg.norm(y[family == f] - means[f], axis=1).mean() for f in range(3))
    gaps = [np.linalg.norm(means[i] - means[j]) for i in range(3) for j in range(i)]
    assert min(gaps) > 3 * spread
    assert tsne(np.zeros((2, 2)), np.zeros((2, 2))).shape == (2, 2)
