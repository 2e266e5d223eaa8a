"""Solid (3D) noise evaluated at surface points, so patterns are continuous across UV seams and the same at
every texture resolution.

Value noise on a periodic random lattice with quintic interpolation, summed in octaves (fbm). Written here in
numpy because none of the listed libraries offers seeded 3D noise at arbitrary points; everything is vectorised
over points and float32.
"""

from __future__ import annotations

import numpy as np

LATTICE = 64  # lattice period per axis; frequencies are chosen so that it never repeats over a hand


def lattice(rng: np.random.Generator) -> np.ndarray:
    """A (LATTICE**3,) float32 lattice of uniform values in [-1, 1], flattened x-fastest."""
    return rng.uniform(-1.0, 1.0, LATTICE ** 3).astype(np.float32)


def value_noise(points: np.ndarray, table: np.ndarray, matrix=None, shift=None) -> np.ndarray:
    """Value noise at `points` (N, 3) @ `matrix` (3, 3) + `shift` (3,) (lattice units; identity and zero by
    default), from a `lattice()` table; (N,) float32 in [-1, 1]."""
    p = np.asarray(points, dtype=np.float32)
    m = np.eye(3, dtype=np.float32) if matrix is None else np.asarray(matrix, np.float32)
    t = np.zeros(3, np.float32) if shift is None else np.asarray(shift, np.float32)
    out = np.empty(len(p), np.float32)
    # In chunks that keep the gathers in cache: about ten times faster than one pass over millions of points.
    # The 3x3 transform is written out (not `@`): BLAS threading makes tiny-matrix products erratic in time.
    for s in range(0, len(p), _CHUNK):
        c = p[s:s + _CHUNK]
        q = c[:, 0:1] * m[0] + c[:, 1:2] * m[1] + c[:, 2:3] * m[2] + t
        out[s:s + len(c)] = _value_noise(q, table)
    return out


_CHUNK = 1 << 16


def _value_noise(p: np.ndarray, table: np.ndarray) -> np.ndarray:
    cell = np.floor(p)
    f = p - cell
    w = f * f * f * (f * (f * 6.0 - 15.0) + 10.0)  # quintic fade: C2-continuous
    i = cell.astype(np.int64) & (LATTICE - 1)
    x0, y0, z0 = i[:, 0], i[:, 1] * LATTICE, i[:, 2] * LATTICE * LATTICE
    x1 = (x0 + 1) & (LATTICE - 1)
    y1 = ((i[:, 1] + 1) & (LATTICE - 1)) * LATTICE
    z1 = ((i[:, 2] + 1) & (LATTICE - 1)) * LATTICE * LATTICE
    wx, wy, wz = w[:, 0], w[:, 1], w[:, 2]

    def along_x(base):
        v = table[base + x0]
        v += wx * (table[base + x1] - v)
        return v

    c00, c10, c01, c11 = along_x(y0 + z0), along_x(y1 + z0), along_x(y0 + z1), along_x(y1 + z1)
    c00 += wy * (c10 - c00)
    c01 += wy * (c11 - c01)
    c00 += wz * (c01 - c00)
    return c00


def fbm(points: np.ndarray, rng: np.random.Generator, scale: float, octaves: int = 2, gain: float = 0.5,
        stretch=(1.0, 1.0, 1.0)) -> np.ndarray:
    """Fractal sum of value noise at `points` (N, 3) in metres; features about `scale` metres across.

    Each octave has its own random rotation and offset (so lattice axes do not show), double the frequency and
    `gain` times the amplitude. `stretch` (3,) divides the coordinates per axis before rotation, e.g. (3, 1, 1)
    elongates features along x. Normalised to unit standard deviation; (N,) float32.
    """
    p = np.asarray(points, dtype=np.float32) / np.asarray(stretch, dtype=np.float32)
    total = np.zeros(len(p), np.float32)
    amp, norm = 1.0, 0.0
    for k in range(octaves):
        rot = _random_rotation(rng).astype(np.float32)
        shift = rng.uniform(0, LATTICE, 3).astype(np.float32)
        total += amp * value_noise(p, lattice(rng), rot * np.float32(2.0 ** k / scale), shift)
        norm += amp * amp
        amp *= gain
    # One octave of this value noise (uniform lattice values, quintic fade) has a standard deviation of ~0.40.
    return total / np.float32(0.40 * np.sqrt(norm))


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def smoothstep(edge0, edge1, x):
    """Hermite step from 0 at edge0 to 1 at edge1 (edges may be reversed), elementwise float32."""
    t = np.clip((np.asarray(x, np.float32) - np.float32(edge0)) / np.float32(edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)
