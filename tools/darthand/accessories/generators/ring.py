"""Finger rings: bands (flat, court, twisted, braided), signet, and stone settings (solitaire prongs, bezel).

Local frame: the finger bone along +X, the ring centred at the origin, its bore the circle of radius
`inner_radius` in the plane x = 0; the top (signet face, stone) on +Y, the dorsal side of the finger.
Atlas slots: 0 metal, 1 signet face, 3 stone.
"""

from __future__ import annotations

import numpy as np

from darthand.accessories import textures as tx
from darthand.accessories.generators.shapes import band, cylinder_z, gem, place, rope, rounded_box, samples_for
from darthand.accessories.mesh import (AccessoryMesh, circle2d, combine, rounded_rect2d,
                                       superellipse2d, sweep)

STYLES = ("flat", "court", "twisted", "braided", "signet", "solitaire", "bezel")
GAP = 0.0001   # 0.1 mm between separate parts, so the union stays a set of disjoint closed solids
X, Y, Z = np.eye(3)


def ring(params: dict, rng: np.random.Generator, texture_size: int = 256) -> AccessoryMesh:
    """A ring of style params["style"] with bore radius params["inner_radius"] (m), band width params["width"]
    and thickness params["thickness"] (m), metal params["metal"], optional stone params["stone"]."""
    r, w, t = float(params["inner_radius"]), float(params["width"]), float(params["thickness"])
    style = params["style"]
    n = samples_for(2 * np.pi * r, 0.0005, 96)
    if style == "flat":
        parts = [band(r, r, rounded_rect2d(0.0, t, w / 2, 24, power=8.0), n)]
    elif style == "court":
        parts = [band(r, r, rounded_rect2d(0.0, t, w / 2, 24, power=2.6), n)]
    elif style == "twisted":
        parts = [_twisted(r, w, t, int(params.get("twists", 8)), n)]
    elif style == "braided":
        parts = rope(r, r, 3, int(params.get("twists", 7)), strand_radius=0.42 * t, spread=0.58 * t,
                     n=2 * n)
    elif style == "signet":
        parts = _signet(r, w, t, params, n)
    elif style in ("solitaire", "bezel"):
        parts = _stone_setting(r, w, t, params, n, style)
    else:
        raise ValueError(f"unknown ring style {style!r}")
    verts, faces, uvs, fuv = combine(parts)
    metal = tx.METALS[params["metal"]]
    tiles = {0: tx.metal(metal, rng, texture_size // 2, roughness=float(params.get("roughness", 0.2)),
                         brushed=style in ("flat", "twisted"))}
    if style == "signet":
        tiles[1] = tx.engraving(metal, rng, texture_size // 2, motif=params.get("motif", "crest"))
    if params.get("stone"):
        tiles[3] = tx.stone(tx.STONES[params["stone"]], rng, texture_size // 2)
    dims = {"inner_radius": r, "inner_diameter": 2 * r, "width": _axial_extent(verts), "thickness": t,
            "outer_radius": float(np.linalg.norm(verts[:, 1:], axis=1).max())}
    dims["ring_size_eu"] = 2 * np.pi * r * 1000.0                 # EU size: inner circumference in mm
    dims["ring_size_us"] = (2 * r * 1000.0 - 11.63) / 0.8128      # US size from inner diameter in mm
    material = {"kind": "metal", "metal": params["metal"], "base_color": list(metal), "metallic": 1.0,
                "roughness": float(params.get("roughness", 0.2))}
    if params.get("stone"):
        material["stone"] = params["stone"]
    return AccessoryMesh(verts, faces, uvs, fuv, material, tx.atlas(tiles, texture_size), dims, len(parts))


def _axial_extent(verts: np.ndarray) -> float:
    return float(verts[:, 0].max() - verts[:, 0].min())


def _twisted(r: float, w: float, t: float, twists: int, n: int):
    """A rounded square section (side t, stretched to width w) turning `twists` quarter-turns per revolution
    (a multiple of the square's symmetry, so the sweep closes), its innermost corner just touching the bore."""
    side = t
    sq = superellipse2d(side / 2, side / 2, 24, power=5.0)
    reach = np.linalg.norm(sq, axis=1).max()
    ang = twists * (np.pi / 2) * np.arange(n) / n
    c, s = np.cos(ang), np.sin(ang)
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)        # (n, 2, 2)
    prof = np.einsum("nij,mj->nmi", rot, sq) + [reach, 0.0]
    prof[..., 1] *= w / side                                                 # stretch across the band width
    return band(r, r, prof, n)


def _signet(r: float, w: float, t: float, params: dict, n: int):
    """A band thickening and widening toward the top, and an oval engraved plate above it."""
    face_w, face_l = float(params.get("face_width", 0.011)), float(params.get("face_length", 0.009))
    top_t = float(params.get("top_thickness", 2.2 * t))
    phi = 2 * np.pi * np.arange(n) / n
    bump = np.cos(np.minimum(np.abs(np.angle(np.exp(1j * phi))), np.pi) / 2) ** 10          # 1 at the top
    base = rounded_rect2d(0.0, 1.0, 0.5, 24, power=3.0)
    prof = np.empty((n, len(base), 2))
    prof[..., 0] = base[None, :, 0] * (t + (top_t - t) * bump)[:, None]
    prof[..., 1] = base[None, :, 1] * (w + (0.8 * face_l - w) * bump)[:, None]
    shank = band(r, r, prof, n)
    plate_t = float(params.get("face_thickness", 0.0012))
    plate = rounded_box(face_w / 2, face_l / 2, 0.0, plate_t, power=2.4, slot=0)
    plate[1] = plate[1].with_uv(slot=1)
    # Footprint x across the finger (Z), y along the bone (X); then the plate's height is Z x X = +Y.
    return [shank] + place(plate, [0, r + top_t + GAP, 0], Z, X)


def _stone_setting(r: float, w: float, t: float, params: dict, n: int, style: str):
    """A court band and a round stone above its top, held by prongs (solitaire) or a bezel tube."""
    shank = band(r, r, rounded_rect2d(0.0, t, w / 2, 24, power=2.6), n)
    g = float(params.get("stone_diameter", 0.005)) / 2
    d = 2 * g
    seat = r + t + 0.0003                                 # culet 0.3 mm above the band
    girdle_y = seat + 0.43 * d
    stone = place(gem(g), [0, girdle_y, 0], Z, X)
    parts = [shank] + stone
    if style == "solitaire":
        pr = max(0.00035, 0.09 * d)
        k = int(params.get("prongs", 4))
        for i in range(k):
            a = np.pi / k + 2 * np.pi * i / k
            px, pz = (g + pr + GAP) * np.cos(a), (g + pr + GAP) * np.sin(a)
            # Prongs stand on the band top (just clear of it at their own z) up past the girdle.
            zn = max(abs(pz) - pr, 0.0)                 # the prong's point nearest the band's crest
            foot = np.sqrt((r + t) ** 2 - zn ** 2) + GAP
            parts += place(cylinder_z(pr, 0.0, girdle_y + 0.1 * d - foot, 8), [px, foot, pz], Z, X)
    else:
        wall = float(params.get("bezel_wall", 0.0005))
        h0, h1 = seat + 0.1 * d, girdle_y + 0.12 * d
        m = samples_for(2 * np.pi * (g + GAP + wall), 0.0004, 48)
        circle = np.column_stack([np.zeros(m), circle2d(g + GAP, m)])
        path = circle[:, [1, 0, 2]]                     # a circle in the XZ plane, about +Y
        n1 = path / np.linalg.norm(path, axis=1, keepdims=True)
        n2 = np.tile(Y, (m, 1))
        prof = rounded_rect2d(0.0, wall, (h1 - h0) / 2, 16, power=6.0) + [0.0, (h0 + h1) / 2]
        parts.append(sweep(path, n1, n2, prof))
    return parts
