"""Printed faces of objects, drawn as small images (linear RGB floats in [0, 1], (H, W, 3)): a can's print, a
bottle's label, a card's face, a phone's screen. Plain shapes in a few colours, each choice from the item's own
generator: enough for a hand's view of the object to show print, not a brand."""

from __future__ import annotations

import numpy as np


def _grid(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """(u, v) pixel-centre coordinates in [0, 1], v up (row 0 is v = 1)."""
    v, u = np.meshgrid((np.arange(height)[::-1] + 0.5) / height, (np.arange(width) + 0.5) / width, indexing="ij")
    return u, v


def _accent(rng: np.random.Generator, color) -> np.ndarray:
    """A colour that stands out against `color`: its complement lifted, or white."""
    base = np.asarray(color, float)
    return np.clip(1.0 - base, 0.05, 0.95) if rng.random() < 0.6 else np.array([0.85, 0.85, 0.83])


def wrap_print(rng: np.random.Generator, color, v_from: float = 0.0, v_to: float = 1.0,
               size: tuple[int, int] = (128, 256)) -> np.ndarray:
    """A can's print or a bottle's label around a cylinder (u around, v up): the base `color`, a wave band in an
    accent colour, a logo block; drawn between heights v_from..v_to (paper white outside)."""
    u, v = _grid(*size)
    t = np.clip((v - v_from) / max(v_to - v_from, 1e-6), 0, 1)
    img = np.broadcast_to(np.asarray(color, float), size + (3,)).copy()
    accent = _accent(rng, color)
    phase, freq, mid = rng.uniform(0, 2 * np.pi), int(rng.integers(1, 4)), rng.uniform(0.35, 0.6)
    wave = mid + 0.08 * np.sin(2 * np.pi * freq * u + phase)
    band = (t > wave) & (t < wave + rng.uniform(0.08, 0.2))
    img[band] = accent
    cu, cv = rng.uniform(0.15, 0.85), rng.uniform(0.7, 0.85)
    logo = (np.abs(u - cu) < 0.12) & (np.abs(t - cv) < 0.07)
    img[logo] = np.array([0.9, 0.9, 0.88]) if accent.mean() < 0.5 else np.array([0.03, 0.03, 0.03])
    img[(v < v_from) | (v > v_to)] = 0.8
    return img


def card_face(rng: np.random.Generator, color, size: tuple[int, int] = (160, 256)) -> np.ndarray:
    """A card's face (u along its width, v along its height): a diagonal shade of `color`, a gold chip, a row of
    number blocks and a logo disc."""
    u, v = _grid(*size)
    base = np.asarray(color, float)
    img = base * (0.75 + 0.5 * (u + v)[..., None] / 2)
    chip = (np.abs(u - 0.2) < 0.07) & (np.abs(v - 0.55) < 0.09)
    img[chip] = np.array([0.75, 0.55, 0.2])
    digits = (v > 0.28) & (v < 0.36) & (u > 0.1) & (u < 0.85) & (((u - 0.1) * 40) % 2.5 < 1.6)
    img[digits] = 0.85 if base.mean() < 0.4 else 0.05
    cx, cy = rng.uniform(0.7, 0.85), rng.uniform(0.6, 0.8)
    img[(u - cx) ** 2 + ((v - cy) * 0.63) ** 2 < 0.006] = _accent(rng, base)
    return np.clip(img, 0, 1)


def screen(rng: np.random.Generator, size: tuple[int, int] = (256, 128)) -> np.ndarray:
    """A phone's screen (u across, v along it): a dark gradient wallpaper, a grid of app squares and a dock."""
    u, v = _grid(*size)
    top, bottom = rng.uniform(0.0, 0.25, 3), rng.uniform(0.0, 0.08, 3)
    img = bottom + (top - bottom) * v[..., None]
    for row in range(5):
        for col in range(4):
            cu, cv = 0.14 + col * 0.24, 0.82 - row * 0.12
            icon = (np.abs(u - cu) < 0.08) & (np.abs(v - cv) < 0.04)
            img[icon] = rng.uniform(0.05, 0.8, 3)
    img[(v < 0.1) & (v > 0.03) & (u > 0.06) & (u < 0.94)] = 0.3
    return np.clip(img, 0, 1)
