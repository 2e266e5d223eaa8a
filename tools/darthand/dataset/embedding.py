"""t-SNE (van der Maaten and Hinton, 2008), the 2-D embedding of DART's pose-coverage figure, in numpy.

Exact: the N x N affinities and the full gradient every step, O(N^2) time and memory per iteration, so it is meant for
the bounded subsample a report draws (a thousand or two points, a few seconds). Deterministic: it starts from the
points' principal components (scaled down, as openTSNE and scikit-learn's "pca" start do) and draws nothing at
random, so a report of the same dataset is the same picture. The project writes its own because its dependencies
have none (scikit-learn would be a new, heavy one for one figure).
"""

from __future__ import annotations

import numpy as np

PERPLEXITY = 30.0
ITERATIONS = 750
EXAGGERATION_ITERATIONS = 250     # early exaggeration (x12) and momentum 0.5, then momentum 0.8
EXAGGERATION = 12.0


def tsne(distances: np.ndarray, start: np.ndarray, perplexity: float = PERPLEXITY,
         iterations: int = ITERATIONS) -> np.ndarray:
    """(N, 2) t-SNE coordinates of N points given their (N, N) distances (any metric) and a (N, 2) start (e.g.
    the first two principal components; rescaled here to a standard deviation of 1e-4)."""
    from threadpoolctl import threadpool_limits

    # (N, N) @ (N, 2) products are too small to share: threaded BLAS made 1,200 points 4x slower on a loaded
    # 2-core machine (13-19 s against 3.5-3.9 s)
    with threadpool_limits(limits=1, user_api="blas"):
        return _tsne(distances, start, perplexity, iterations)


def _tsne(distances: np.ndarray, start: np.ndarray, perplexity: float, iterations: int) -> np.ndarray:
    n = len(distances)
    if n < 3:
        return np.zeros((n, 2))
    # float32 in the descent: four times faster than float64, and the result is a picture
    p = joint_affinities(np.asarray(distances, np.float64) ** 2, min(perplexity, (n - 1) / 3)).astype(np.float32)
    y = np.asarray(start, np.float64) - np.mean(start, 0)
    y = (y * (1e-4 / max(float(y[:, 0].std()), 1e-300))).astype(np.float32)
    rate = max(n / EXAGGERATION / 4, 50.0)               # scikit-learn's "auto" learning rate
    step, gains = np.zeros_like(y), np.ones_like(y)
    exaggerated = p * np.float32(EXAGGERATION)
    for it in range(iterations):
        early = it < EXAGGERATION_ITERATIONS
        grad = kl_gradient(exaggerated if early else p, y)
        # delta-bar-delta gains: grow where the gradient keeps its direction against the last step, shrink otherwise
        gains = np.where(np.sign(grad) != np.sign(step), gains + 0.2, gains * 0.8).clip(0.01)
        step = ((0.5 if early else 0.8) * step - rate * gains * grad).astype(np.float32)
        y += step
        y -= y.mean(0)
    return y.astype(np.float64)


def joint_affinities(d2: np.ndarray, perplexity: float) -> np.ndarray:
    """Symmetric (N, N) input affinities P from squared distances, summing to 1: (P_c + P_c^T) / 2N of the
    conditional ones (`conditional_affinities`)."""
    cond = conditional_affinities(d2, perplexity)
    p = cond + cond.T
    return np.maximum(p / p.sum(), 1e-12)


def conditional_affinities(d2: np.ndarray, perplexity: float) -> np.ndarray:
    """(N, N) p_j|i from squared distances: each row a Gaussian over the other points whose precision is found by
    bisection so that the row's entropy is log(perplexity)."""
    n = len(d2)
    off = ~np.eye(n, dtype=bool)
    d = np.where(off, d2, 0.0)
    d = np.where(off, d - np.min(np.where(off, d2, np.inf), 1, keepdims=True), 0.0)   # row minimum 0: no underflow
    target = np.log(perplexity)
    lo, hi = np.zeros(n), np.full(n, np.inf)
    beta = np.full(n, 1.0 / max(float(np.median(d2[off])), 1e-12))
    for _ in range(64):
        w = np.exp(-d * beta[:, None]) * off
        total = w.sum(1)
        cond = w / total[:, None]
        entropy = np.log(total) + beta * (d * cond).sum(1)
        flat = entropy > target                          # too flat: a larger precision
        lo, hi = np.where(flat, beta, lo), np.where(flat, hi, beta)
        beta = np.where(np.isinf(hi), 2 * beta, (lo + hi) / 2)
    return cond


def kl_gradient(p: np.ndarray, y: np.ndarray) -> np.ndarray:
    """dKL(P || Q)/dy (N, 2) for the Student-t output kernel w_ij = 1 / (1 + |y_i - y_j|^2)."""
    sq = (y * y).sum(1)
    w = 1.0 / (1.0 + np.maximum(sq[:, None] + sq[None] - 2 * y @ y.T, 0))
    np.fill_diagonal(w, 0)
    m = (p - w / w.sum()) * w
    return 4 * (m.sum(1)[:, None] * y - m @ y)
