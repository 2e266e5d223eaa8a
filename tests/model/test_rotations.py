"""Rotation maths: closed-form hard cases against an 80-digit reference, round-trip and invariant properties.

Truth comes from (a) Rodrigues' formula evaluated in `decimal` at 80 significant digits on the exact binary value
of each input (series for small angles, reduction modulo a 80-digit pi for large ones), (b) matrices and
quaternions written down in closed form, (c) scipy's Rotation as an independent float64 implementation.

Tolerances scale with the angle t: an input angle t is itself only known to ~eps * t, so no float evaluation of
R(v) can beat an absolute error of ~eps * max(1, t).
"""

from __future__ import annotations

import math
from decimal import Decimal, localcontext

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from darthand.errors import InputError
from darthand.model.rotations import (
    axis_angle_to_matrix,
    axis_angle_to_quaternion,
    check_finite_pose,
    matrix_to_axis_angle,
    matrix_to_quaternion,
    quaternion_conjugate,
    quaternion_multiply,
    quaternion_to_axis_angle,
    quaternion_to_matrix,
    slerp,
    wrap_axis_angle,
)

PI = math.pi
DTYPES = [np.float64, np.float32]
EPS = {np.float64: float(np.finfo(np.float64).eps), np.float32: float(np.finfo(np.float32).eps)}
PROPS = settings(max_examples=60, deadline=None)


# ---------------------------------------------------------------------------------------------------------------
# 80-digit reference


def _dec_pi() -> Decimal:
    """pi to the current precision (the recipe from the `decimal` documentation)."""
    with localcontext() as ctx:
        ctx.prec += 2
        three = Decimal(3)
        lasts, t, s, n, na, d, da = 0, three, 3, 1, 0, 0, 24
        while s != lasts:
            lasts = s
            n, na = n + na, na + 8
            d, da = d + da, da + 32
            t = (t * n) / d
            s += t
    return +s


def _dec_series(x2: Decimal, first: int) -> Decimal:
    """sum_k (-1)^k x2^k / (2k + first)!  (first = 1: sin(x)/x, first = 2: (1 - cos x)/x^2)."""
    term = Decimal(1) / math.factorial(first)
    total, k = Decimal(0), 0
    while term != 0 and (total == 0 or abs(term) > abs(total) * Decimal("1e-85")):
        total += term
        k += 1
        term = -term * x2 / ((2 * k + first - 1) * (2 * k + first))
    return total


def _dec_sin_cos(t: Decimal) -> tuple[Decimal, Decimal]:
    two_pi = 2 * _dec_pi()
    r = t - (t / two_pi).to_integral_value() * two_pi  # |r| <= pi
    r2 = r * r
    return r * _dec_series(r2, 1), 1 - r2 * _dec_series(r2, 2)


def reference_matrix(v) -> np.ndarray:
    """R(v) = I + A K + B K^2 in 80-digit decimal arithmetic on the exact binary values of v, rounded to float64."""
    with localcontext() as ctx:
        ctx.prec = 80
        x, y, z = (Decimal(float(c)) for c in v)
        t2 = x * x + y * y + z * z
        if t2 < 1:
            a, b = _dec_series(t2, 1), _dec_series(t2, 2)
        else:
            t = t2.sqrt()
            s, c = _dec_sin_cos(t)
            a, b = s / t, (1 - c) / t2
        rows = [
            [1 - b * (y * y + z * z), b * x * y - a * z, b * x * z + a * y],
            [b * x * y + a * z, 1 - b * (x * x + z * z), b * y * z - a * x],
            [b * x * z - a * y, b * y * z + a * x, 1 - b * (x * x + y * y)],
        ]
        return np.array([[float(e) for e in row] for row in rows])


def _axis(*c) -> np.ndarray:
    u = np.array(c, dtype=np.float64)
    return u / np.linalg.norm(u)


def skew(v) -> np.ndarray:
    x, y, z = v
    return np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]], dtype=np.float64)


def closed_form_rotation(angle_cos: float, angle_sin: float, one_minus_cos: float, u) -> np.ndarray:
    """cos I + sin [u]_x + (1 - cos) u u^T, the three trigonometric values given separately (no cancellation)."""
    u = np.asarray(u, dtype=np.float64)
    return angle_cos * np.eye(3) + angle_sin * skew(u) + one_minus_cos * np.outer(u, u)


# ---------------------------------------------------------------------------------------------------------------
# axis_angle_to_matrix: hard-case table

OBLIQUE = _axis(1, -2, 3)
HARD_AXIS_ANGLES = {
    "zero": [0.0, 0.0, 0.0],
    "1e-300_x": [1e-300, 0.0, 0.0],
    "1e-300_oblique": list(1e-300 * OBLIQUE),
    "1e-12_oblique": list(1e-12 * OBLIQUE),
    "1e-8_oblique": list(1e-8 * OBLIQUE),
    "1e-4_oblique": list(1e-4 * OBLIQUE),
    "taylor_edge_below": list(1.2e-4 * OBLIQUE),  # float64 switches series at t = eps^(1/4) ~ 1.22e-4
    "taylor_edge_above": list(1.25e-4 * OBLIQUE),
    "f32_taylor_edge": list(0.0186 * OBLIQUE),  # float32 switch at ~0.0186
    "pi_x": [PI, 0.0, 0.0],
    "pi_y": [0.0, PI, 0.0],
    "pi_z": [0.0, 0.0, PI],
    "pi_oblique": list(PI * _axis(2, 3, 6)),
    "pi_minus_1e-9": list((PI - 1e-9) * OBLIQUE),
    "pi_plus_1e-9": list((PI + 1e-9) * OBLIQUE),
    "two_pi_z": [0.0, 0.0, 2 * PI],
    "4pi_plus_small": list((4 * PI + 1e-6) * OBLIQUE),
    "1000pi_plus_0.3_x": [1000 * PI + 0.3, 0.0, 0.0],
    "1000pi_plus_0.3_oblique": list((1000 * PI + 0.3) * OBLIQUE),
    "negative_x_half_pi": [-PI / 2, 0.0, 0.0],
    "negative_oblique": list(-2.5 * _axis(1, 1, 1)),
    "neg_1000pi_plus_0.3": list(-(1000 * PI + 0.3) * _axis(0, 3, -4)),
}


@pytest.mark.parametrize("dtype", DTYPES, ids=["f64", "f32"])
@pytest.mark.parametrize("v", list(HARD_AXIS_ANGLES.values()), ids=list(HARD_AXIS_ANGLES))
def test_axis_angle_to_matrix_hard_cases(v, dtype):
    v = np.array(v, dtype=dtype)
    R = axis_angle_to_matrix(v)
    assert R.dtype == dtype and R.shape == (3, 3)
    truth = reference_matrix(v)  # of the exact value the function received (the float32 rounding included)
    t = float(np.linalg.norm(v.astype(np.float64)))
    eps = EPS[dtype]
    err = np.abs(R.astype(np.float64) - truth)
    off = ~np.eye(3, dtype=bool)
    # Off-diagonal entries are O(t) for small t and must be relatively exact there (R = I + K + ...);
    # for large t the input angle's own rounding (~eps t) bounds what any evaluation can do.
    assert err[off].max() <= 8 * eps * t
    assert err[~off].max() <= 8 * eps * max(1.0, t)


def test_exact_at_zero_and_first_order_below_series_switch():
    assert np.array_equal(axis_angle_to_matrix(np.zeros(3)), np.eye(3))
    for v in (np.array([1e-300, -2e-300, 3e-300]), np.array([3e-20, 1e-20, -2e-20])):
        R = axis_angle_to_matrix(v)
        assert np.array_equal(R - np.eye(3), skew(v))  # quadratic term below the last bit


@pytest.mark.parametrize(
    "direction", [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.6, -0.8, 0.0]], ids=["x", "y", "z", "oblique"]
)
def test_derivative_at_zero_is_skew(direction):
    e = np.array(direction, dtype=np.float64)
    h = 1e-6
    central = (axis_angle_to_matrix(h * e) - axis_angle_to_matrix(-h * e)) / (2 * h)
    np.testing.assert_allclose(central, skew(e), rtol=0, atol=1e-10)
    h = 1e-9  # one-sided: R(h e) = I + h K + h^2 K^2 / 2 -> the error is ~h
    one_sided = (axis_angle_to_matrix(h * e) - np.eye(3)) / h
    np.testing.assert_allclose(one_sided, skew(e), rtol=0, atol=2e-9)


def test_derivative_just_above_zero_matches_reference():
    """Directional derivative at a small non-zero v, against a central difference of the 80-digit reference."""
    v, d, h = 1e-5 * OBLIQUE, _axis(3, 1, -1), 1e-7
    got = (axis_angle_to_matrix(v + h * d) - axis_angle_to_matrix(v - h * d)) / (2 * h)
    want = (reference_matrix(v + h * d) - reference_matrix(v - h * d)) / (2 * h)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-8)


# ---------------------------------------------------------------------------------------------------------------
# matrix_to_axis_angle: hard-case table

U = _axis(1, 2, 2)  # (1, 2, 2)/3


def _rot(angle_cos, angle_sin, one_minus_cos, u=U):
    return closed_form_rotation(angle_cos, angle_sin, one_minus_cos, u)


HARD_MATRICES = {
    # id: (R, expected axis-angle, sign_free) -- sign_free: at exactly pi, +aa and -aa are both right
    "identity": (np.eye(3), np.zeros(3), False),
    "pi_x_diag": (np.diag([1.0, -1.0, -1.0]), np.array([PI, 0, 0]), False),
    "pi_y_diag": (np.diag([-1.0, 1.0, -1.0]), np.array([0, PI, 0]), False),
    "pi_z_diag": (np.diag([-1.0, -1.0, 1.0]), np.array([0, 0, PI]), False),
    "pi_oblique": (2 * np.outer(U, U) - np.eye(3), PI * U, True),
    "pi_minus_1e-9": (_rot(-math.cos(1e-9), math.sin(1e-9), 1 + math.cos(1e-9)), (PI - 1e-9) * U, False),
    "pi_minus_1e-6": (_rot(-math.cos(1e-6), math.sin(1e-6), 1 + math.cos(1e-6)), (PI - 1e-6) * U, False),
    # rotation by pi + d about u is rotation by pi - d about -u
    "pi_plus_1e-9": (_rot(-math.cos(1e-9), -math.sin(1e-9), 1 + math.cos(1e-9)), -(PI - 1e-9) * U, False),
    "half_pi_neg_z": (np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]]), np.array([0, 0, -PI / 2]), False),
    "1e-10": (_rot(math.cos(1e-10), math.sin(1e-10), 2 * math.sin(0.5e-10) ** 2), 1e-10 * U, False),
    "1e-5": (_rot(math.cos(1e-5), math.sin(1e-5), 2 * math.sin(0.5e-5) ** 2), 1e-5 * U, False),
    "2.5_rad": (_rot(math.cos(2.5), math.sin(2.5), 1 - math.cos(2.5)), 2.5 * U, False),
}


@pytest.mark.parametrize("dtype", DTYPES, ids=["f64", "f32"])
@pytest.mark.parametrize("case", list(HARD_MATRICES.values()), ids=list(HARD_MATRICES))
def test_matrix_to_axis_angle_hard_cases(case, dtype):
    R, expected, sign_free = case
    aa = matrix_to_axis_angle(R.astype(dtype))
    assert aa.dtype == dtype
    eps = EPS[dtype]
    angle = np.linalg.norm(expected)
    tol = 16 * eps * (angle if angle < 1e-3 else 1.0)  # relative for small angles (0 at the identity)
    if dtype == np.float32 and 0 < PI - angle < 1e-5:
        tol = 2e-6  # float32 cannot tell pi - 1e-9 from pi; the angle is right to a few ulps of pi
        sign_free = True
    err = np.abs(aa - expected).max()
    if sign_free:
        err = min(err, np.abs(aa + expected).max())
    assert err <= tol, (aa, expected)
    assert np.linalg.norm(aa.astype(np.float64)) <= PI * (1 + 4 * eps)  # the norm of the rounded components


def test_matrix_to_axis_angle_exact_pi_diagonals_have_positive_axis():
    for i in range(3):
        R = -np.eye(3)
        R[i, i] = 1
        expected = np.zeros(3)
        expected[i] = PI
        assert np.array_equal(matrix_to_axis_angle(R), expected)


# ---------------------------------------------------------------------------------------------------------------
# quaternions: hard cases

SQ = math.sqrt(0.5)
HARD_QUATERNIONS = {
    # id: (q, expected axis-angle)
    "identity": ([1.0, 0, 0, 0], [0, 0, 0]),
    "minus_identity": ([-1.0, 0, 0, 0], [0, 0, 0]),
    "pi_x": ([0.0, 1, 0, 0], [PI, 0, 0]),
    "pi_minus_y": ([0.0, 0, -1, 0], [0, -PI, 0]),
    "half_pi_z": ([SQ, 0, 0, SQ], [0, 0, PI / 2]),
    "negated_half_pi_z": ([-SQ, 0, 0, -SQ], [0, 0, PI / 2]),
    "w_negative_3half_pi_z": ([math.cos(3 * PI / 4), 0, 0, math.sin(3 * PI / 4)], [0, 0, -PI / 2]),
    "scaled_by_2": ([2 * SQ, 0, 2 * SQ, 0], [0, PI / 2, 0]),
    "tiny_1e-200": ([1.0, 0.5e-200, 0, 0], [1e-200, 0, 0]),
    "tiny_1e-9": ([math.cos(0.5e-9), *(math.sin(0.5e-9) * U)], list(1e-9 * U)),
    "near_pi_w_negative": ([-math.sin(0.5e-9), *(math.cos(0.5e-9) * U)], list(-(PI - 1e-9) * U)),
}


@pytest.mark.parametrize("q, expected", list(HARD_QUATERNIONS.values()), ids=list(HARD_QUATERNIONS))
def test_quaternion_to_axis_angle_hard_cases(q, expected):
    aa = quaternion_to_axis_angle(np.array(q))
    expected = np.array(expected, dtype=np.float64)
    scale = max(np.linalg.norm(expected), 1e-300) if np.linalg.norm(expected) < 1e-3 else 1.0
    np.testing.assert_allclose(aa, expected, rtol=0, atol=8 * EPS[np.float64] * scale)


@pytest.mark.parametrize(
    "R, expected",
    [
        (np.eye(3), [1, 0, 0, 0]),
        (np.diag([1.0, -1, -1]), [0, 1, 0, 0]),
        (np.diag([-1.0, 1, -1]), [0, 0, 1, 0]),
        (np.diag([-1.0, -1, 1]), [0, 0, 0, 1]),
        (np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]), [SQ, 0, 0, SQ]),
        (2 * np.outer(U, U) - np.eye(3), [0, *U]),
    ],
    ids=["identity", "pi_x", "pi_y", "pi_z", "half_pi_z", "pi_oblique"],
)
def test_matrix_to_quaternion_hard_cases(R, expected):
    q = matrix_to_quaternion(R)
    np.testing.assert_allclose(q, expected, rtol=0, atol=4 * EPS[np.float64])
    assert q[0] >= 0


def test_matrix_to_quaternion_output_is_unit_for_perturbed_matrices():
    rng = np.random.default_rng(7)
    R = axis_angle_to_matrix(rng.normal(size=(50, 3))) * (1 + 1e-3 * rng.normal(size=(50, 3, 3)))
    q = matrix_to_quaternion(R)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1, rtol=0, atol=4 * EPS[np.float64])


@pytest.mark.parametrize(
    "aa, expected",
    [
        ([0, 0, 3 * PI / 2], [0, 0, -PI / 2]),
        ([2 * PI, 0, 0], [0, 0, 0]),
        ([0, -(1000 * PI + 0.3), 0], [0, -0.3, 0]),
        (list((4 * PI + 1.0) * U), list(1.0 * U)),
        ([0, 0, -2.0], [0, 0, -2.0]),
    ],
    ids=["3pi/2", "2pi", "-(1000pi+0.3)", "4pi+1", "in_range_negative"],
)
def test_wrap_axis_angle_closed_form(aa, expected):
    # reduction uses the float 2 pi: ~1e-13 rad off at 1000 pi, below one ulp of the input angle there
    np.testing.assert_allclose(wrap_axis_angle(np.array(aa)), expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("angle", [0.0, 1e-300, 1e-9, 1e-4, 1.2e-4, 1e-3, 1.0, PI, 2 * PI, 1000 * PI + 0.3])
def test_axis_angle_to_quaternion_closed_form(angle):
    q = axis_angle_to_quaternion(angle * U)
    eps = EPS[np.float64]
    np.testing.assert_allclose(q[0], math.cos(angle / 2), rtol=0, atol=2 * eps * max(1.0, angle))
    # the vector part is ~angle/2 for small angles and must be relatively exact there
    np.testing.assert_allclose(q[1:], math.sin(angle / 2) * U, rtol=0, atol=4 * eps * angle)


# ---------------------------------------------------------------------------------------------------------------
# slerp: hard cases against the closed form of a rotation about a fixed axis


def _about(angle, u=U):
    """Quaternion of the rotation by `angle` about unit u, written out (no double-cover canonicalisation)."""
    return np.array([math.cos(angle / 2), *(math.sin(angle / 2) * np.asarray(u))])


@pytest.mark.parametrize(
    "alpha, delta",
    [(0.3, 1e-12), (0.3, 1e-9), (0.3, 1e-6), (0.3, 1e-3), (0.3, 1e-2), (0.3, 0.05), (1.0, 2.0), (0.0, PI / 2)],
    ids=["1e-12", "1e-9", "1e-6", "1e-3", "1e-2", "0.05", "2rad", "quarter"],
)
def test_slerp_same_axis_is_uniform_in_angle(alpha, delta):
    t = np.linspace(0, 1, 11)
    got = slerp(_about(alpha), _about(alpha + delta), t)
    want = np.stack([_about(alpha + ti * delta) for ti in t])
    np.testing.assert_allclose(got, want, rtol=0, atol=4e-16)


def test_slerp_equal_and_antipodal_return_the_rotation():
    q = _about(1.2)
    t = np.array([0.0, 0.25, 0.5, 1.0])
    for other in (q, -q):
        got = slerp(q, other, t)
        assert np.all(np.isfinite(got))
        np.testing.assert_allclose(got, np.broadcast_to(q, (4, 4)), rtol=0, atol=4e-16)


def test_slerp_nearly_antipodal_takes_the_short_arc():
    # -q(alpha + d) is the same rotation as q(alpha + d): the result must stay within d of q(alpha), up to sign.
    # t = 1 returns the flipped end point +q(alpha + d), the same rotation as the q1 given.
    alpha, d = 0.7, 1e-7
    got = slerp(_about(alpha), -_about(alpha + d), np.array([0.0, 0.5, 1.0]))
    want = np.stack([_about(alpha), _about(alpha + d / 2), _about(alpha + d)])
    np.testing.assert_allclose(got, want, rtol=0, atol=4e-16)


def test_slerp_shortest_arc_through_double_cover():
    # q1 is a rotation by 3 pi/2 about z written with w < 0; the short way from identity is -pi/2 about z.
    q1 = _about(3 * PI / 2, [0, 0, 1])
    mid = slerp(np.array([1.0, 0, 0, 0]), q1, 0.5)
    np.testing.assert_allclose(quaternion_to_matrix(mid), axis_angle_to_matrix([0, 0, -PI / 4]), atol=1e-15)


def test_slerp_broadcasting():
    q0, q1 = _about(0.1), _about(0.9)
    assert slerp(q0, q1, np.linspace(0, 1, 5)).shape == (5, 4)
    Q0, Q1 = np.stack([q0] * 3), np.stack([q1] * 3)
    assert slerp(Q0, Q1, 0.5).shape == (3, 4)
    out = slerp(Q0, Q1, np.array([0.0, 0.5, 1.0]))
    np.testing.assert_allclose(out, np.stack([q0, _about(0.5), q1]), atol=4e-16)
    assert slerp(q0.astype(np.float32), q1.astype(np.float32), 0.5).dtype == np.float32


# ---------------------------------------------------------------------------------------------------------------
# properties

ANGLE_SCALES = st.one_of(
    st.floats(0, 20),
    st.floats(1e-12, 1e-3),
    st.floats(PI - 1e-6, PI + 1e-6),
    st.sampled_from([0.0, PI, 2 * PI]),
)


@st.composite
def axis_angle_batches(draw, dtype, n=4):
    axes = draw(arrays(np.float64, (n, 3), elements=st.floats(-1, 1)))
    norms = np.linalg.norm(axes, axis=-1, keepdims=True)
    assume(np.all(norms > 1e-2))
    angles = np.array([draw(ANGLE_SCALES) for _ in range(n)])[:, None]
    return (axes / norms * angles).astype(dtype)


@st.composite
def unit_quaternion_batches(draw, dtype, n=4):
    q = draw(arrays(np.float64, (n, 4), elements=st.floats(-1, 1)))
    norms = np.linalg.norm(q, axis=-1, keepdims=True)
    assume(np.all(norms > 1e-2))
    return (q / norms).astype(dtype)


# Round-trip tolerance per dtype, relative to max(1, angle).
TOL = {np.float64: 1e-13, np.float32: 4e-6}


def assert_le(err, bound):
    """err <= bound elementwise, with broadcasting."""
    err, bound = np.broadcast_arrays(np.asarray(err, dtype=np.float64), np.asarray(bound, dtype=np.float64))
    bad = ~(err <= bound)
    assert not bad.any(), f"{bad.sum()} over tolerance: err {err[bad].max():.3g}, bound {bound[bad].min():.3g}"


def axis_angle_error(back, aa, dtype):
    """(B,) max-abs distance of axis-angles `back` from wrap_axis_angle(aa), where the sign is free at pi."""
    wrapped = wrap_axis_angle(aa)
    near_pi = PI - _angles(wrapped) < (1e-12 if dtype == np.float64 else 1e-5)
    err = np.abs(back - wrapped).max(axis=-1)
    return np.where(near_pi, np.minimum(err, np.abs(back + wrapped).max(axis=-1)), err)


def _angles(aa):
    return np.linalg.norm(aa.astype(np.float64), axis=-1)


@pytest.mark.parametrize("dtype", DTYPES, ids=["f64", "f32"])
@PROPS
@given(data=st.data())
def test_matrix_is_rotation_and_matches_scipy(dtype, data):
    aa = data.draw(axis_angle_batches(dtype))
    R = axis_angle_to_matrix(aa)
    assert R.dtype == dtype and R.shape == (4, 3, 3)
    R64 = R.astype(np.float64)
    scale = np.maximum(1, _angles(aa))[:, None, None]
    assert_le(np.abs(R64 @ R64.transpose(0, 2, 1) - np.eye(3)), 8 * EPS[dtype])
    assert_le(np.abs(np.linalg.det(R64) - 1), 8 * EPS[dtype])
    truth = Rotation.from_rotvec(aa.astype(np.float64)).as_matrix()
    assert_le(np.abs(R64 - truth), 8 * EPS[dtype] * scale)


@pytest.mark.parametrize("dtype", DTYPES, ids=["f64", "f32"])
@PROPS
@given(data=st.data())
def test_axis_angle_matrix_round_trip(dtype, data):
    aa = data.draw(axis_angle_batches(dtype))
    R = axis_angle_to_matrix(aa)
    back = matrix_to_axis_angle(R)
    assert back.dtype == dtype
    assert np.all(_angles(back) <= PI * (1 + 4 * EPS[dtype]))
    scale = np.maximum(1, _angles(aa))
    # same rotation, always
    assert_le(np.abs(axis_angle_to_matrix(back) - R).max(axis=(1, 2)), 8 * TOL[dtype] * scale)
    # same vector as the wrapped input, except where pi makes the sign free
    assert_le(axis_angle_error(back, aa, dtype), TOL[dtype] * scale)


@pytest.mark.parametrize("dtype", DTYPES, ids=["f64", "f32"])
@PROPS
@given(data=st.data())
def test_axis_angle_quaternion_round_trip(dtype, data):
    aa = data.draw(axis_angle_batches(dtype))
    q = axis_angle_to_quaternion(aa)
    assert q.dtype == dtype
    scale = np.maximum(1, _angles(aa))
    assert_le(np.abs(np.linalg.norm(q.astype(np.float64), axis=-1) - 1), 4 * EPS[dtype])
    R = axis_angle_to_matrix(aa)
    assert_le(np.abs(quaternion_to_matrix(q) - R).max(axis=(1, 2)), TOL[dtype] * scale)
    back = quaternion_to_axis_angle(q)
    assert_le(axis_angle_error(back, aa, dtype), TOL[dtype] * scale)
    # -q is the same rotation
    assert_le(np.abs(quaternion_to_axis_angle(-q) - back), TOL[dtype] * scale[:, None])


@pytest.mark.parametrize("dtype", DTYPES, ids=["f64", "f32"])
@PROPS
@given(data=st.data())
def test_quaternion_matrix_round_trip(dtype, data):
    q = data.draw(unit_quaternion_batches(dtype))
    R = quaternion_to_matrix(q)
    assert R.dtype == dtype
    back = matrix_to_quaternion(R)
    assert back.dtype == dtype and np.all(back[:, 0] >= 0)
    canonical = np.where(q[:, :1] < 0, -q, q)
    err = np.abs(back - canonical).max(axis=-1)
    sign_free = np.abs(q[:, 0]) < 10 * EPS[dtype]
    err = np.where(sign_free, np.minimum(err, np.abs(back + canonical).max(axis=-1)), err)
    assert_le(err, 8 * EPS[dtype])
    assert_le(np.abs(quaternion_to_matrix(back) - R), 16 * EPS[dtype])
    truth = Rotation.from_quat(q.astype(np.float64)[:, [1, 2, 3, 0]]).as_matrix()
    assert_le(np.abs(R - truth), 8 * EPS[dtype])


@pytest.mark.parametrize("dtype", DTYPES, ids=["f64", "f32"])
@PROPS
@given(data=st.data())
def test_quaternion_product_and_conjugate(dtype, data):
    a = data.draw(unit_quaternion_batches(dtype))
    b = data.draw(unit_quaternion_batches(dtype))
    identity = quaternion_multiply(a, quaternion_conjugate(a))
    assert identity.dtype == dtype
    np.testing.assert_allclose(identity, np.broadcast_to([1, 0, 0, 0], a.shape), rtol=0, atol=4 * EPS[dtype])
    composed = quaternion_to_matrix(quaternion_multiply(a, b))
    np.testing.assert_allclose(composed, quaternion_to_matrix(a) @ quaternion_to_matrix(b), atol=16 * EPS[dtype])


def _arc(p, q):
    """Rotation angle (in [0, pi]) between the rotations of unit quaternions p and q, in float64.

    Twice the angle between p and the nearer of +-q, that angle taken as 2 atan2(|p - q|, |p + q|), which unlike
    arccos of the dot product is accurate when the two nearly coincide.
    """
    p, q = p.astype(np.float64), q.astype(np.float64)
    q = np.where(np.sum(p * q, axis=-1, keepdims=True) < 0, -q, q)
    return 4 * np.arctan2(np.linalg.norm(p - q, axis=-1), np.linalg.norm(p + q, axis=-1))


@pytest.mark.parametrize("dtype", DTYPES, ids=["f64", "f32"])
@PROPS
@given(data=st.data(), t=st.floats(0, 1))
def test_slerp_properties(dtype, data, t):
    q0 = data.draw(unit_quaternion_batches(dtype))
    q1 = data.draw(unit_quaternion_batches(dtype))
    eps = EPS[dtype]
    np.testing.assert_allclose(slerp(q0, q1, 0.0), q0, rtol=0, atol=4 * eps)
    shortest_q1 = np.where(np.sum(q0 * q1, axis=-1, keepdims=True) < 0, -q1, q1)
    np.testing.assert_allclose(slerp(q0, q1, 1.0), shortest_q1, rtol=0, atol=4 * eps)
    qt = slerp(q0, q1, t)
    assert qt.dtype == dtype
    assert_le(np.abs(np.linalg.norm(qt.astype(np.float64), axis=-1) - 1), 4 * eps)
    # on the shortest arc, at the fraction t of the way
    total = _arc(q0, q1)
    tol = TOL[dtype]
    assert_le(np.abs(_arc(q0, qt) - t * total), tol)
    assert_le(np.abs(_arc(qt, q1) - (1 - t) * total), tol)
    mid = slerp(q0, q1, 0.5)
    assert_le(np.abs(_arc(q0, mid) - _arc(mid, q1)), tol)


@PROPS
@given(data=st.data())
def test_wrap_axis_angle_keeps_the_rotation(data):
    aa = data.draw(axis_angle_batches(np.float64))
    w = wrap_axis_angle(aa)
    assert np.all(_angles(w) <= PI * (1 + 4 * EPS[np.float64]))
    scale = np.maximum(1, _angles(aa))[:, None, None]
    assert_le(np.abs(axis_angle_to_matrix(w) - axis_angle_to_matrix(aa)), 1e-13 * scale)


# ---------------------------------------------------------------------------------------------------------------
# dtypes, shapes, input errors


BATCH_CASES = [
    (axis_angle_to_matrix, np.zeros((2, 5, 3))),
    (matrix_to_axis_angle, np.broadcast_to(np.eye(3), (2, 5, 3, 3))),
    (axis_angle_to_quaternion, np.zeros((2, 5, 3))),
    (quaternion_to_axis_angle, np.broadcast_to([1.0, 0, 0, 0], (2, 5, 4))),
    (quaternion_to_matrix, np.broadcast_to([1.0, 0, 0, 0], (2, 5, 4))),
    (matrix_to_quaternion, np.broadcast_to(np.eye(3), (2, 5, 3, 3))),
    (quaternion_conjugate, np.broadcast_to([1.0, 0, 0, 0], (2, 5, 4))),
    (wrap_axis_angle, np.zeros((2, 5, 3))),
]


@pytest.mark.parametrize("func, arg", BATCH_CASES, ids=[func.__name__ for func, _ in BATCH_CASES])
def test_batch_shapes_and_dtypes(func, arg):
    arg = np.array(arg)  # a writable copy, to see that the input is left alone
    before = arg.copy()
    out64 = func(arg)
    assert np.array_equal(arg, before)
    assert out64.shape[:2] == (2, 5) and out64.dtype == np.float64
    assert func(arg.astype(np.float32)).dtype == np.float32
    assert func(arg.astype(np.float16)).dtype == np.float32
    assert func(arg.astype(np.int64)).dtype == np.float64
    assert func(arg[0, 0]).shape == out64.shape[2:]
    assert func(arg[:0]).shape == (0,) + out64.shape[1:]


@pytest.mark.parametrize(
    "func, bad",
    [
        (axis_angle_to_matrix, np.zeros((4, 2))),
        (axis_angle_to_matrix, np.zeros(48)),
        (matrix_to_axis_angle, np.zeros((4, 3))),
        (quaternion_to_matrix, np.zeros((4, 3))),
        (axis_angle_to_matrix, np.array(["a", "b", "c"])),
        (axis_angle_to_matrix, np.zeros(3, dtype=complex)),
    ],
    ids=["aa_4x2", "aa_48", "R_4x3", "q_4x3", "strings", "complex"],
)
def test_bad_shapes_and_types_raise_input_error(func, bad):
    with pytest.raises(InputError):
        func(bad)


def test_check_finite_pose_names_first_offending_index():
    pose = np.zeros((5, 48))
    pose[4, 0] = np.inf
    pose[3, 17] = np.nan
    with pytest.raises(InputError) as exc:
        check_finite_pose(pose)
    assert str(exc.value) == "pose: non-finite value nan at [3, 17] (batch 3, joint 5, component 2)"

    pose = np.zeros((2, 16, 3), dtype=np.float32)
    pose[1, 4, 0] = -np.inf
    expected = r"^hand pose: non-finite value -inf at \[1, 4, 0\] \(batch 1, joint 4, component 0\)$"
    with pytest.raises(InputError, match=expected):
        check_finite_pose(pose, name="hand pose")

    single = np.zeros(48)
    single[10] = np.inf
    with pytest.raises(InputError, match=r"^pose: non-finite value inf at \[10\] \(joint 3, component 1\)$"):
        check_finite_pose(single)


def test_check_finite_pose_accepts_finite_and_rejects_non_numbers():
    assert check_finite_pose(np.zeros((3, 48))) is None
    assert check_finite_pose(np.arange(48)) is None
    assert check_finite_pose([[0.1, -0.2, 3.0]] * 16) is None
    with pytest.raises(InputError, match="^pose: expected real numbers"):
        check_finite_pose(np.array(["x"] * 48))
