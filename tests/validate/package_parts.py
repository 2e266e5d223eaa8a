"""What the validation suite's good packages are made of: the catalogue ids they carry, their ring and their
textures. A module of its own (not conftest.py) so test files can import it by a name no other folder uses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio

# Catalogue ids of the committed specs (the packages have no built catalogue beside them).
TEXTURE_IDS = ("light_tattoos_00", "base_freckles_00")
RING_ID, GLOVE_ID = "ring_01_court_gold", "glove_01_latex"
RING_JOINT = 5            # middle2
RING_GAP = 0.0008         # metres between the ring's inner surface and the hand's
GESTURES = (["flat", "fist_like"], np.stack([np.zeros(48), np.r_[np.zeros(3), np.tile([0, 0, 0.6], 15)]]))


def write_png(path: Path, width: int, height: int, seed: int) -> Path:
    rgb = np.random.default_rng(seed).random((height, width, 3)).astype(np.float32)
    buf = oiio.ImageBuf(oiio.ImageSpec(width, height, 3, oiio.UINT8))
    buf.set_pixels(oiio.ROI(), rgb)
    path.parent.mkdir(parents=True, exist_ok=True)
    assert buf.write(str(path)), buf.geterror()
    return path


def ring_mesh(model, joint: int = RING_JOINT, segments: int = 24, tube: int = 6, minor: float = 0.0005):
    """A closed torus around the finger tube (axis X) at the joint's x, its inner surface RING_GAP outside the
    tube's inscribed circle (the tube is a 16-gon of radius 3 cm)."""
    centre = np.asarray(model.J_regressor @ model.v_template)[joint]
    inradius = 0.03 * np.cos(np.pi / 16)
    major = inradius + RING_GAP + minor
    u = 2 * np.pi * np.arange(segments)[:, None] / segments
    v = 2 * np.pi * np.arange(tube)[None, :] / tube
    r = major + minor * np.cos(v) + 0 * u
    x = np.broadcast_to(centre[0] + minor * np.sin(v), r.shape)
    verts = np.stack([x, r * np.cos(u) + 0 * x, r * np.sin(u) + 0 * x], -1)
    faces = []
    for i in range(segments):
        for j in range(tube):
            a, b = i * tube + j, ((i + 1) % segments) * tube + j
            c, d = i * tube + (j + 1) % tube, ((i + 1) % segments) * tube + (j + 1) % tube
            faces += [(a, b, d), (a, d, c)]
    verts = verts.reshape(-1, 3)
    faces = np.array(faces)
    # outward winding: positive signed volume
    a, b, c = (verts[faces[:, k]] for k in range(3))
    if np.einsum("ij,ij->i", a, np.cross(b, c)).sum() < 0:
        faces = faces[:, ::-1].copy()
    return verts, faces
