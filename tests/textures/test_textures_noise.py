"""Solid noise: seeded, unit variance, continuous in 3D (so seams cannot show), lattice values interpolated."""

import numpy as np

from darthand.textures.noise import LATTICE, fbm, lattice, smoothstep, value_noise


def test_value_noise_interpolates_the_lattice():
    table = lattice(np.random.default_rng(0))
    pts = np.array([[0, 0, 0], [3, 5, 7], [LATTICE - 1, 2, 9]], float)
    expected = [table[int(z) * LATTICE * LATTICE + int(y) * LATTICE + int(x)] for x, y, z in pts]
    assert np.allclose(value_noise(pts, table), expected)
    # Periodic with the lattice.
    assert np.allclose(value_noise(pts + LATTICE, table), value_noise(pts, table), atol=1e-5)


def test_fbm_is_seeded_unit_variance_and_continuous():
    rng = np.random.default_rng(1)
    p = rng.random((200_000, 3)) * [0.25, 0.05, 0.12]
    a = fbm(p, np.random.default_rng(7), 0.01, octaves=2)
    b = fbm(p, np.random.default_rng(7), 0.01, octaves=2)
    c = fbm(p, np.random.default_rng(8), 0.01, octaves=2)
    assert np.array_equal(a, b) and not np.allclose(a, c)
    assert 0.85 < a.std() < 1.15 and abs(a.mean()) < 0.15
    # A tenth of a millimetre moves a 1 cm noise by a small fraction of its spread.
    step = fbm(p + [1e-4, 0, 0], np.random.default_rng(7), 0.01, octaves=2)
    assert np.abs(step - a).max() < 0.25 * a.std()


def test_smoothstep():
    x = np.array([-1.0, 0.0, 0.25, 0.5, 1.0, 2.0])
    assert np.allclose(smoothstep(0.0, 1.0, x), [0, 0, 0.15625, 0.5, 1, 1])
    assert np.allclose(smoothstep(1.0, 0.0, x), 1 - smoothstep(0.0, 1.0, x))
