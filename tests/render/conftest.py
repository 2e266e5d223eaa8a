"""Fixtures of the renderer's tests: the open hand with the DART wrist, a generated skin texture, a ring around the
index finger's middle phalanx (built here, not by the other stages)."""

from __future__ import annotations

import numpy as np
import pytest
from render_scenes import RING_JOINT, ring_around, write_image

from darthand.textures.loader import TextureSet
from darthand.model.load import load_model
from darthand.model.wrist import add_wrist
from darthand.render.assets import HandAssets

@pytest.fixture(scope="session")
def hand():
    return add_wrist(load_model("open"))


@pytest.fixture(scope="session")
def texture_files(tmp_path_factory):
    """A 256^2 sRGB skin texture with a soft gradient and a 4 x 4 grid of darker spots, and a roughness map."""
    folder = tmp_path_factory.mktemp("tex")
    y, x = np.mgrid[0:256, 0:256] / 255.0
    base = np.array([224, 172, 140], float)
    img = base * (0.85 + 0.15 * x[..., None]) * (1 - 0.25 * ((np.sin(8 * np.pi * x) * np.sin(8 * np.pi * y)) > 0.9)
                                                  [..., None])
    albedo = write_image(folder / "skin.png", np.clip(img, 0, 255).astype(np.uint8))
    rough = write_image(folder / "rough.png", np.full((256, 256), 140, np.uint8))
    return TextureSet("skin_test", albedo, rough)


@pytest.fixture(scope="session")
def ring(hand):
    return ring_around(hand, RING_JOINT, RING_JOINT + 1)


@pytest.fixture
def assets(hand, texture_files, ring):
    """Fresh per test (it caches the last pose)."""
    return HandAssets(hand, {texture_files.id: texture_files}, texture_files.id, {ring.id: ring}, "open+wrist")
