"""Rotation maths of the rig: axis-angle, rotation matrices and unit quaternions, batched over leading dimensions.

Shapes: axis-angle (..., 3) in radians (direction = axis, length = angle), matrices (..., 3, 3) acting on column
vectors, quaternions (..., 4) ordered (w, x, y, z) with the Hamilton product, so that
quaternion_to_matrix(quaternion_multiply(a, b)) == quaternion_to_matrix(a) @ quaternion_to_matrix(b).

Precision: every function computes in the dtype of its input (float32 and float64 are kept, float16 is raised to
float32, integers and booleans become float64) and is accurate to a few ulps of that dtype over the whole domain:
at angle 0, at tiny angles (Taylor series instead of 0/0), at pi (where the antisymmetric part of a matrix
vanishes) and far beyond 2 pi.

Why not scipy.spatial.transform.Rotation (used as an independent check in the tests): it always computes and
returns float64, while the forward pass runs in float32 on B x 16 vectors per call, where this Rodrigues kernel is
also 1.5-3x faster (see benchmarks/rotations.py); the rest follows so the conventions (w first, dtype
kept, angle ranges) are the same across the module.
"""

from __future__ import annotations

import numpy as np

from darthand.errors import InputError

__all__ = [
    "axis_angle_to_matrix",
    "matrix_to_axis_angle",
    "axis_angle_to_quaternion",
    "quaternion_to_axis_angle",
    "quaternion_to_matrix",
    "matrix_to_quaternion",
    "quaternion_multiply",
    "quaternion_conjugate",
    "slerp",
    "wrap_axis_angle",
    "check_finite_pose",
]


# --------------------------------------------------------------------------------------------------------------
# input coercion


def _float_dtype(dtype: np.dtype) -> np.dtype:
    """The dtype the maths runs in: floats keep theirs (float16 -> float32), integers and booleans -> float64."""
    if dtype.kind == "f":
        return np.dtype(np.float32) if dtype.itemsize < 4 else dtype
    if dtype.kind in "biu":
        return np.dtype(np.float64)
    raise InputError(f"expected real numbers, got dtype {dtype}")


def _as_array(a, name: str) -> np.ndarray:
    """np.asarray(a), with numpy's complaints about unreadable input turned into an InputError naming `name`."""
    try:
        return np.asarray(a)
    except (TypeError, ValueError) as exc:  # ragged nested lists, objects numpy cannot read
        raise InputError(f"{name}: not a numeric array ({exc})") from None


def _as_float(a, name: str, tail: tuple[int, ...]) -> np.ndarray:
    """`a` as an array of its float dtype (see `_float_dtype`) whose trailing shape is `tail`."""
    arr = _as_array(a, name)
    try:
        dt = _float_dtype(arr.dtype)
    except InputError as exc:
        raise InputError(f"{name}: {exc}") from None
    if tail and (arr.ndim < len(tail) or arr.shape[-len(tail):] != tail):
        want = ", ".join(["..."] + [str(n) for n in tail])
        raise InputError(f"{name}: expected shape ({want}), got {arr.shape}")
    return arr.astype(dt, copy=False)


def _small_threshold(dtype: np.dtype) -> float:
    """Below this squared angle the two-term Taylor series are exact to rounding (error ~ t^4 / 120 < eps)."""
    return float(np.sqrt(np.finfo(dtype).eps))


# --------------------------------------------------------------------------------------------------------------
# axis-angle <-> matrix


def _rodrigues_coefficients(t2: np.ndarray, work: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A = sin(t)/t and B = (1 - cos t)/t^2 from the squared angles t2 (N,); returns the views work[0], work[1].

    work: (3, N) scratch of t2's dtype, overwritten. Both coefficients come from one tangent of the half angle,
    tau = tan(t/2), with h = tau/t and c = 1/(1 + tau^2) = cos^2(t/2):
        A = 2 h c,   B = 2 sin^2(t/2)/t^2 = A h,  or  B = 2 (1 - c)/t^2 once c < 1/2
    (the second form is more accurate towards t = pi; it halves the orthonormality error there). Nothing cancels
    (1 - cos t would lose every digit of a small t, in float32 already at t ~ 1e-3), and it costs one
    transcendental instead of two: numpy's tan is vectorised (~1 ulp in float64) while its float64 sin/cos are
    scalar libm calls, about ten times slower. tau stays finite: no float is an odd multiple of pi/2 (tau^2 < 1e40
    for every finite float32/float64 t). For t^2 < sqrt(eps) A and B take their two-term Taylor series (error
    ~ t^4/120 < eps), which also covers t = 0 and squared angles that underflowed.
    """
    a, b, tau = work
    small = t2 < _small_threshold(t2.dtype)
    any_small = bool(small.any())
    t = np.sqrt(t2, out=b)
    t2_safe = t2
    if any_small:  # keep the divisions below finite; these entries are overwritten at the end
        t[small] = 1
        t2_safe = np.where(small, 1, t2)
    np.multiply(t, 0.5, out=tau)
    np.tan(tau, out=tau)
    h = np.divide(tau, t, out=b)
    np.multiply(tau, tau, out=tau)
    far = tau > 1  # t/2 nearer an odd multiple of pi/2 than a multiple of pi
    tau += 1
    c = np.reciprocal(tau, out=tau)
    np.multiply(h, c, out=a)
    a *= 2
    np.multiply(a, h, out=b)  # B = A h
    b_far = np.subtract(1, c, out=c)  # B = 2 (1 - c)/t^2
    b_far *= 2
    b_far /= t2_safe
    # Select b_far where far without a masked (branchy, ~10x slower) copy: both approximate B to a few ulps, so
    # b_far - b is exact (Sterbenz) and b + (b_far - b) * 1 == b_far exactly, b + (...) * 0 == b.
    b_far -= b
    b_far *= far
    b += b_far
    if any_small:
        ts = t2[small]
        a[small] = 1 - ts / 6
        b[small] = 0.5 - ts / 24
    return a, b


def axis_angle_to_matrix(aa) -> np.ndarray:
    """Rotation matrices (..., 3, 3), C-contiguous, of axis-angle vectors aa (..., 3), radians.

    Rodrigues' formula written on the unnormalised vector v: R = I + A K + B K^2 with K = [v]_x, A = sin(t)/t,
    B = (1 - cos t)/t^2, t = |v|. No axis normalisation, so R(v) = I + K + K^2/2 + O(|v|^3) holds down to v = 0
    (the derivative at 0 is exact) and angles of any size (pi, 2 pi, 1000 pi) are exact to rounding.
    Using K^2 = v v^T - t^2 I the entries are R_ij = B v_i v_j - A eps_ijk v_k off the diagonal and
    R_ii = 1 - B (v_j^2 + v_k^2) on it.
    """
    v = _as_float(aa, "aa", (3,))
    shape = v.shape[:-1]
    v = v.reshape(-1, 3)
    out = np.empty((v.shape[0], 3, 3), dtype=v.dtype)
    # Every intermediate lives in one (7, N) block of contiguous rows, allocated after (and smaller than) the
    # output: contiguous operands make the ufuncs several times faster than strided ones, and one small block
    # instead of ~20 temporaries lets malloc reuse the memory across calls instead of returning it to the OS and
    # page-faulting it back in on every call (measured: that costs more than all of the arithmetic).
    work = np.empty((7, v.shape[0]), dtype=v.dtype)
    x, y, z = xyz = work[0:3]
    np.copyto(xyz, v.T)
    t2, s1 = work[3], work[4]
    np.multiply(x, x, out=t2)
    t2 += np.multiply(y, y, out=s1)
    t2 += np.multiply(z, z, out=s1)
    a, b = _rodrigues_coefficients(t2, work[4:7])
    s1, s2 = t2, work[6]  # t2 and the coefficients' scratch row are free again

    for i, (p, q) in enumerate(((y, z), (x, z), (x, y))):
        np.multiply(p, p, out=s1)
        s1 += np.multiply(q, q, out=s2)
        s1 *= b
        np.subtract(1, s1, out=out[:, i, i])
    # (i, j, k) with eps_ijk = +1: R_ij = B v_i v_j - A v_k, R_ji = B v_i v_j + A v_k
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        np.multiply(b, xyz[i], out=s1)
        s1 *= xyz[j]
        np.multiply(a, xyz[k], out=s2)
        np.subtract(s1, s2, out=out[:, i, j])
        np.add(s1, s2, out=out[:, j, i])
    return out.reshape(shape + (3, 3))


def matrix_to_axis_angle(R) -> np.ndarray:
    """Axis-angle vectors (..., 3) of rotation matrices R (..., 3, 3); the angle is in [0, pi].

    Goes through `matrix_to_quaternion` (largest-component method): near pi the axis comes from the symmetric
    part (largest diagonal) and its sign from the antisymmetric part; the angle is 2 atan2(|q_xyz|, |w|), well
    conditioned at 0 and at pi (unlike arccos of the trace). At exactly pi the axis has its largest component
    positive.
    """
    return quaternion_to_axis_angle(matrix_to_quaternion(R))


def wrap_axis_angle(aa) -> np.ndarray:
    """The equivalent axis-angle vectors (..., 3) with angle in [0, pi] (the same rotation matrices).

    Angles are reduced modulo the float 2 pi; for an angle of 1000 pi the reduction error (~1e-13 rad) is below
    one ulp of the input angle itself. Vectors already in [0, pi] are returned unchanged (as a copy).
    """
    v = _as_float(aa, "aa", (3,))
    t = np.sqrt(np.sum(v * v, axis=-1))
    two_pi = 2 * np.pi
    r = np.remainder(t, two_pi)
    r = np.where(r > np.pi, r - two_pi, r)  # signed angle in (-pi, pi]; negative flips the axis
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(t > np.pi, r / np.where(t > np.pi, t, 1), 1).astype(v.dtype, copy=False)
    return v * scale[..., None]


# --------------------------------------------------------------------------------------------------------------
# quaternions


def axis_angle_to_quaternion(aa) -> np.ndarray:
    """Unit quaternions (..., 4), (w, x, y, z), of axis-angle vectors aa (..., 3).

    q = (cos(t/2), sin(t/2)/t * v); not canonicalised, so angles in (pi, 3 pi) give w < 0 (same rotation as -q).
    """
    v = _as_float(aa, "aa", (3,))
    t2 = np.sum(v * v, axis=-1)
    small = t2 < _small_threshold(v.dtype)
    t = np.sqrt(t2)
    safe_t = np.where(small, 1, t)
    k = np.where(small, 0.5 - t2 / 48, np.sin(0.5 * safe_t) / safe_t)
    return np.concatenate([np.cos(0.5 * t)[..., None], k[..., None] * v], axis=-1)


def quaternion_to_axis_angle(q) -> np.ndarray:
    """Axis-angle vectors (..., 3) of quaternions q (..., 4), (w, x, y, z); angle in [0, pi].

    q and -q give the same result (the shortest rotation). Scale-invariant, so q need not be exactly unit (but
    must be non-zero). The angle is 2 atan2(|xyz|, |w|); the factor angle/|xyz| uses its Taylor series
    2/|w| (1 - r^2/3), r = |xyz|/|w|, where r is small.
    """
    q = _as_float(q, "q", (4,))
    w, xyz = q[..., 0], q[..., 1:]
    s2 = np.sum(xyz * xyz, axis=-1)
    s, c = np.sqrt(s2), np.abs(w)
    angle = 2 * np.arctan2(s, c)
    small = s2 < _small_threshold(q.dtype) * (c * c)
    safe_s, safe_c = np.where(small, 1, s), np.where(small, c, 1)
    factor = np.where(small, (2 - (2 / 3) * s2 / (safe_c * safe_c)) / safe_c, angle / safe_s)
    factor = np.where(w < 0, -factor, factor)
    return factor[..., None] * xyz


def quaternion_to_matrix(q) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions q (..., 4), (w, x, y, z).

    Uses s = 2/|q|^2, so a non-unit (non-zero) q gives the rotation of q/|q|.
    """
    q = _as_float(q, "q", (4,))
    w, x, y, z = np.moveaxis(q, -1, 0)
    s = 2 / np.sum(q * q, axis=-1)
    sx, sy, sz = s * x, s * y, s * z
    wx, wy, wz = w * sx, w * sy, w * sz
    xx, xy, xz = x * sx, x * sy, x * sz
    yy, yz, zz = y * sy, y * sz, z * sz
    rows = [
        [1 - (yy + zz), xy - wz, xz + wy],
        [xy + wz, 1 - (xx + zz), yz - wx],
        [xz - wy, yz + wx, 1 - (xx + yy)],
    ]
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


def matrix_to_quaternion(R) -> np.ndarray:
    """Unit quaternions (..., 4), (w, x, y, z), w >= 0, of rotation matrices R (..., 3, 3).

    Shepperd's method: of the four expressions 4 q_i^2 (1 + trace, 1 + R00 - R11 - R22, ...), the largest picks
    the component that is divided by; the other three come from sums/differences of off-diagonal pairs. Every
    candidate row below equals 4 q_i * q, so normalising the chosen row gives q (and a unit quaternion also for a
    slightly non-orthonormal R).
    """
    m = _as_float(R, "R", (3, 3))
    m00, m01, m02 = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    m10, m11, m12 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    m20, m21, m22 = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    d = np.stack(
        [1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], axis=-1
    )
    k = np.argmax(d, axis=-1)
    dk = np.take_along_axis(d, k[..., None], axis=-1)[..., 0]
    a21, a02, a10 = m21 - m12, m02 - m20, m10 - m01  # 4 w (x, y, z)
    s01, s02, s12 = m10 + m01, m02 + m20, m21 + m12  # 4 (xy, xz, yz)
    candidates = np.stack(
        [
            np.stack([dk, a21, a02, a10], axis=-1),
            np.stack([a21, dk, s01, s02], axis=-1),
            np.stack([a02, s01, dk, s12], axis=-1),
            np.stack([a10, s02, s12, dk], axis=-1),
        ],
        axis=-2,
    )
    q = np.take_along_axis(candidates, k[..., None, None], axis=-2)[..., 0, :]
    q /= np.sqrt(np.sum(q * q, axis=-1, keepdims=True))
    return np.where(q[..., :1] < 0, -q, q)


def quaternion_multiply(a, b) -> np.ndarray:
    """Hamilton product a * b (..., 4), broadcasting; the rotation of a*b is R(a) @ R(b) (b applied first)."""
    a, b = _common_float(_as_float(a, "a", (4,)), _as_float(b, "b", (4,)))
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quaternion_conjugate(q) -> np.ndarray:
    """Conjugates (w, -x, -y, -z), (..., 4); the inverse rotation for unit q."""
    q = _as_float(q, "q", (4,))
    return q * np.array([1, -1, -1, -1], dtype=q.dtype)


def slerp(q0, q1, t) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions (..., 4) along the shortest arc; t = 0 gives q0.

    t (...) broadcasts against the leading dimensions of q0 and q1 (e.g. q0, q1 of shape (4,) and t of shape
    (N,) give (N, 4)); values outside [0, 1] extrapolate. q1 is replaced by -q1 when q0 . q1 < 0 (same rotation,
    shorter arc). The arc angle is W = 2 atan2(|q0 - q1|, |q0 + q1|) (accurate at every angle, unlike arccos
    of the dot product near 1); for W^2 < sqrt(eps) the weights sin(a W)/sin(W) take their Taylor series
    a (1 + (1 - a^2) W^2/6), i.e. a normalised lerp with a second-order correction, so nothing divides by ~0
    (and antipodal inputs, the same rotation, return q0). The result is normalised.
    """
    q0, q1 = _common_float(_as_float(q0, "q0", (4,)), _as_float(q1, "q1", (4,)))
    dtype = q0.dtype
    t = _as_float(t, "t", ()).astype(dtype, copy=False)[..., None]
    q1 = np.where(np.sum(q0 * q1, axis=-1, keepdims=True) < 0, -q1, q1)
    omega = 2 * np.arctan2(_norm(q0 - q1), _norm(q0 + q1))
    small = omega * omega < _small_threshold(dtype)
    safe = np.where(small, 1, omega)
    u = 1 - t
    w0 = np.where(small, u * (1 + (1 - u * u) * (omega * omega) / 6), np.sin(u * safe) / np.sin(safe))
    w1 = np.where(small, t * (1 + (1 - t * t) * (omega * omega) / 6), np.sin(t * safe) / np.sin(safe))
    q = w0 * q0 + w1 * q1
    return q / _norm(q)


def _common_float(*arrays: np.ndarray) -> list[np.ndarray]:
    """The arrays in their common float dtype (float32 with float64 -> float64)."""
    dtype = np.result_type(*arrays)
    return [arr.astype(dtype, copy=False) for arr in arrays]


def _norm(q: np.ndarray) -> np.ndarray:
    """Euclidean norm over the last axis, kept as a length-1 axis."""
    return np.sqrt(np.sum(q * q, axis=-1, keepdims=True))


# --------------------------------------------------------------------------------------------------------------
# validation


def check_finite_pose(pose, name: str = "pose") -> None:
    """Raise InputError naming the first NaN/Inf entry of `pose` (C order), e.g.

    "pose: non-finite value nan at [3, 17] (batch 3, joint 5, component 2)".

    Poses are axis-angle, (B, 48), (48,), (B, 16, 3) or (16, 3); the joint/component reading is added when the
    last axis is 3 (with a joint axis before it) or a multiple of 3. Non-numeric input is rejected as well.
    """
    arr = _as_array(pose, name)
    if arr.dtype.kind in "biu":
        return
    if arr.dtype.kind != "f":
        raise InputError(f"{name}: expected real numbers, got dtype {arr.dtype}")
    finite = np.isfinite(arr)
    if finite.all():
        return
    index = tuple(int(i) for i in np.unravel_index(int(np.argmin(finite)), arr.shape))
    value = float(arr[index])
    raise InputError(f"{name}: non-finite value {value!r} at {list(index)}{_describe_pose_index(index, arr.shape)}")


def _describe_pose_index(index: tuple[int, ...], shape: tuple[int, ...]) -> str:
    """' (batch b, joint j, component c)' for pose layouts, '' when the shape has no such reading."""
    if not shape:
        return ""
    if shape[-1] == 3 and len(shape) >= 2:
        batch, joint, comp = index[:-2], index[-2], index[-1]
    elif shape[-1] % 3 == 0 and shape[-1] > 3:
        batch, joint, comp = index[:-1], index[-1] // 3, index[-1] % 3
    else:
        return ""
    parts = []
    if batch:
        parts.append(f"batch {batch[0]}" if len(batch) == 1 else f"batch {list(batch)}")
    parts += [f"joint {joint}", f"component {comp}"]
    return " (" + ", ".join(parts) + ")"
