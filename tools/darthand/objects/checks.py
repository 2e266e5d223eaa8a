"""What the catalogue build refuses: meshes that are not closed and outward, hold NaN or infinite numbers, or have
an absurd size, and licences outside the allow-list. Each refusal is an InputError of one line naming the item."""

from __future__ import annotations

import numpy as np
import trimesh

from darthand.errors import InputError

ALLOWED_LICENCES = ("CC0-1.0", "MIT", "BSD-2-Clause", "BSD-3-Clause", "BSD", "Apache-2.0", "CC-BY-4.0")
SIZE_RANGE_M = (0.005, 0.6)       # the largest extent of something a hand holds


def check_licence(licence: str, where: str) -> None:
    """InputError unless `licence` (an SPDX name) is one the catalogue may ship."""
    if licence not in ALLOWED_LICENCES:
        raise InputError(f"{where}: licence {licence!r} is not one of {', '.join(ALLOWED_LICENCES)}")


def check_mesh(vertices: np.ndarray, faces: np.ndarray, where: str) -> None:
    """InputError unless the mesh is finite, of a size a hand holds (largest extent 5 mm..60 cm), closed
    (watertight), consistently wound and outward (positive volume)."""
    if not np.isfinite(vertices).all():
        raise InputError(f"{where}: the mesh holds NaN or infinite coordinates")
    if len(faces) < 4:
        raise InputError(f"{where}: the mesh has {len(faces)} faces, too few to be closed")
    extent = float((vertices.max(axis=0) - vertices.min(axis=0)).max())
    lo, hi = SIZE_RANGE_M
    if not lo <= extent <= hi:
        raise InputError(f"{where}: absurd size, largest extent {extent * 1000:.4g} mm is outside "
                         f"{lo * 1000:g} mm..{hi * 100:g} cm")
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    if not mesh.is_watertight:
        raise InputError(f"{where}: the mesh is not closed (edges not shared by exactly two faces)")
    if not mesh.is_winding_consistent:
        raise InputError(f"{where}: the mesh's faces are not consistently wound")
    if not mesh.volume > 0:
        raise InputError(f"{where}: the mesh is inside out or flat (volume {mesh.volume:.3g} m^3)")
