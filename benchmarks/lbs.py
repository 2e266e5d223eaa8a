"""LBS throughput (poses/s) at several batch sizes in float32 and float64, and float32's error against float64.

The model is the wrist-enhanced open hand when the template is present (build/model/right.npz if built), otherwise
a MANO-sized synthetic model; its vertex count is reported with the figures.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks._common import bench_model
from darthand.model.forward import forward

BATCHES = (1, 64, 1024, 4096)


def poses_per_second(model, B: int, dtype, seconds: float = 1.0) -> float:
    """Best-of-repeats throughput of `forward` on B random poses."""
    rng = np.random.default_rng(B)
    poses = rng.uniform(-np.pi, np.pi, (B, 48)).astype(dtype)
    forward(model, poses, dtype=dtype)
    best, spent = np.inf, 0.0
    while spent < seconds or best == np.inf:
        t = time.perf_counter()
        forward(model, poses, dtype=dtype)
        dt = time.perf_counter() - t
        best, spent = min(best, dt), spent + dt
    return B / best


def float32_error(model, n: int = 10_000, chunk: int = 1000) -> float:
    """Max vertex distance (m) between float32 and float64 forward passes over n random poses in [-pi, pi]."""
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(n // chunk):
        p = rng.uniform(-np.pi, np.pi, (chunk, 48))
        a = forward(model, p, dtype=np.float64).vertices
        b = forward(model, p.astype(np.float32), dtype=np.float32).vertices
        worst = max(worst, float(np.linalg.norm(a - b, axis=-1).max()))
    return worst


def torch_reference(model, B: int = 1024, seconds: float = 1.0) -> float | None:
    """Poses/s of the same formula written the usual PyTorch way (as smplx's `lbs` does it), float32 on the CPU.

    Only when PyTorch happens to be installed: it is a yardstick, not a dependency.
    """
    try:
        import torch
    except ImportError:
        return None
    V = model.num_vertices
    f32 = dict(dtype=torch.float32)
    v_t = torch.tensor(model.v_template, **f32)
    posedirs = torch.tensor(model.posedirs.reshape(V * 3, -1).T, **f32)
    weights = torch.tensor(model.weights, **f32)
    joints = torch.tensor(model.J_regressor @ model.v_template, **f32)
    parents = model.parents.tolist()
    pose = torch.tensor(np.random.default_rng(B).uniform(-np.pi, np.pi, (B, 48)), **f32)

    def rodrigues(aa):
        angle = torch.norm(aa + 1e-8, dim=1, keepdim=True)
        x, y, z = torch.split(aa / angle, 1, dim=1)
        zero = torch.zeros_like(x)
        K = torch.cat([zero, -z, y, z, zero, -x, -y, x, zero], 1).view(-1, 3, 3)
        s, c = torch.sin(angle)[:, :, None], torch.cos(angle)[:, :, None]
        return torch.eye(3, **f32)[None] + s * K + (1 - c) * torch.bmm(K, K)

    def lbs(pose):
        R = rodrigues(pose.view(-1, 3)).view(B, 16, 3, 3)
        feat = (R[:, 1:] - torch.eye(3, **f32)).view(B, -1)
        v_posed = v_t[None] + (feat @ posedirs).view(B, V, 3)
        rel = joints.clone()
        rel[1:] -= joints[parents[1:]]
        local = torch.cat([torch.cat([R, rel[None, :, :, None].expand(B, -1, -1, -1)], 3),
                           torch.tensor([0, 0, 0, 1.0], **f32).expand(B, 16, 1, 4)], 2)
        chain = [local[:, 0]]
        for i in range(1, 16):
            chain.append(chain[parents[i]] @ local[:, i])
        A = torch.stack(chain, 1)
        A[:, :, :3, 3] -= (A[:, :, :3, :3] @ joints[None, :, :, None])[..., 0]
        T = (weights @ A.view(B, 16, 16)).view(B, V, 4, 4)
        return (T[:, :, :3, :3] @ v_posed[..., None])[..., 0] + T[:, :, :3, 3]

    with torch.no_grad():
        lbs(pose)
        best, spent = np.inf, 0.0
        while spent < seconds:
            t = time.perf_counter()
            lbs(pose)
            dt = time.perf_counter() - t
            best, spent = min(best, dt), spent + dt
    return B / best


def mano_sized_model():
    """A model with MANO's wrist-enhanced sizes (842 vertices, 1666 faces, dense correctives): the forward pass
    costs the same for any geometry of these sizes, so this stands in for the licensed MANO file."""
    from darthand.model.hand_model import HandModel
    from darthand.model.layout import MANO_PARENTS

    rng = np.random.default_rng(0)
    V = 842
    w = rng.random((V, 16)) ** 4
    return HandModel.create(v_template=0.1 * rng.standard_normal((V, 3)), faces=rng.integers(0, V, (1666, 3)),
                            weights=w / w.sum(1, keepdims=True), posedirs=1e-3 * rng.standard_normal((V, 3, 135)),
                            J_regressor=np.abs(rng.standard_normal((16, V))) / V, parents=MANO_PARENTS,
                            tip_ids=np.arange(5), shapedirs=1e-3 * rng.standard_normal((V, 3, 10)))


def throughput(model) -> dict:
    return {np.dtype(dtype).name: {f"B={B}": round(poses_per_second(model, B, dtype)) for B in BATCHES}
            for dtype in (np.float32, np.float64)}


def run() -> dict:
    model, name = bench_model()
    out = {"model": name, "vertices": model.num_vertices, "poses_per_second": throughput(model)}
    mano = mano_sized_model()
    out["mano_sized"] = {"vertices": mano.num_vertices, "poses_per_second": throughput(mano)}
    out["float32_max_vertex_error_m"] = float32_error(model)
    ref = torch_reference(model)
    if ref is not None:
        out["torch_reference_float32_B=1024_poses_per_second"] = round(ref)
        out["mano_sized"]["torch_reference_float32_B=1024_poses_per_second"] = round(torch_reference(mano))
    out["goal"] = "float32 B=1024 >= 60000 poses/s, float32 error <= 1e-6 m"
    return out
