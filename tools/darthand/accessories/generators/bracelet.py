"""Bracelets: bangles, chains, beads on a cord, cuffs, braided cords, charm bracelets.

Local frame as for watches: forearm axis +X, bore ellipse (inner_a along +Y, inner_b along Z) at x = 0, dorsal
side +Y. Atlas slots: 0 metal (or the cord), 1 beads / charms, 2 secondary.
"""

from __future__ import annotations

import numpy as np

from darthand.accessories import textures as tx
from darthand.accessories.generators.shapes import (arc_length_frames, band, chain, offset_perimeter, place, rope,
                                                    samples_for)
from darthand.accessories.mesh import (AccessoryMesh, circle2d, combine, ellipse, ellipse_normals, ellipse_perimeter,
                                       heart2d, rounded_rect2d, stacked_solid, star2d, superellipse2d, sweep)

STYLES = ("bangle", "chain", "beads", "cuff", "cord", "charm")
GAP = 0.0002
X = np.array([1.0, 0.0, 0.0])


def bracelet(params: dict, rng: np.random.Generator, texture_size: int = 256) -> AccessoryMesh:
    """A bracelet of style params["style"] around the bore (params["inner_a"], params["inner_b"])."""
    a, b = float(params["inner_a"]), float(params["inner_b"])
    style = params["style"]
    half = texture_size // 2
    tiles = {}
    material = {"kind": style, "metallic": 1.0, "roughness": float(params.get("roughness", 0.25))}
    if style == "bangle":
        w, t = float(params["width"]), float(params["thickness"])
        parts = [band(a, b, rounded_rect2d(0.0, t, w / 2, 24, power=float(params.get("profile_power", 2.2))))]
    elif style == "cuff":
        parts = [_cuff(a, b, params)]
    elif style in ("chain", "charm"):
        parts, pts, tan = chain(a, b, float(params["wire"]), slot=0)
        if style == "charm":
            parts += _charms(a, b, float(params["wire"]), params, rng)
            tiles[1] = tx.metal(tx.METALS[params.get("charm_metal", params["metal"])], rng, half, 0.2, False)
    elif style == "beads":
        parts = _beads(a, b, params)
        colors = [tx.STONES.get(c, c) if isinstance(c, str) else c for c in params["bead_colors"]]
        tiles[1] = tx.stripes(colors, half, roughness=float(params.get("bead_roughness", 0.3)))
        tiles[0] = tx.fabric(params.get("cord_color", (0.05, 0.05, 0.05)), params.get("cord_color", (0.05,) * 3),
                             rng, half, stripes=0)
        material.update(metallic=0.0, roughness=float(params.get("bead_roughness", 0.3)))
    elif style == "cord":
        t = float(params["thickness"])
        parts = rope(a, b, int(params.get("strands", 3)), int(params.get("twists", 9)), strand_radius=0.42 * t,
                     spread=0.58 * t)
        cols = params.get("cord_colors", [(0.5, 0.1, 0.05), (0.8, 0.7, 0.5), (0.1, 0.2, 0.4)])
        parts = [p.with_uv(slot=0, uv_rect=(0, 1 - (j + 1) / len(parts), 1, 1 - j / len(parts)))
                 for j, p in enumerate(parts)]
        tiles[0] = tx.stripes(cols, half, roughness=0.8)
        material.update(metallic=0.0, roughness=0.8)
    else:
        raise ValueError(f"unknown bracelet style {style!r}")
    if 0 not in tiles:
        tiles[0] = tx.metal(tx.METALS[params["metal"]], rng, half, float(params.get("roughness", 0.25)),
                            brushed=style == "cuff")
    if "metal" in params:
        material.update(metal=params["metal"], base_color=list(tx.METALS[params["metal"]]))
    verts, faces, uvs, fuv = combine(parts)
    dims = {"inner_a": a, "inner_b": b, "inner_circumference": ellipse_perimeter(a, b),
            "width": float(np.ptp(verts[:, 0])),
            "thickness": float((np.linalg.norm(verts[:, 1:] / [a, b], axis=1).max() - 1) * min(a, b))}
    return AccessoryMesh(verts, faces, uvs, fuv, material, tx.atlas(tiles, texture_size), dims, len(parts))


def _cuff(a: float, b: float, params: dict):
    """An open C-shaped band, its opening (params["opening"] radians) on the palmar side (-Y)."""
    w, t = float(params["width"]), float(params["thickness"])
    opening = float(params.get("opening", 1.0))
    n = samples_for(ellipse_perimeter(a, b), 0.001, 96)
    # t from the opening's one edge round the dorsal side to the other: ellipse(., phase) starts at t = phase.
    start = np.pi + opening / 2
    tt = start + (2 * np.pi - opening) * np.arange(n) / (n - 1)
    path = np.stack([np.zeros(n), a * np.cos(tt), b * np.sin(tt)], 1)
    nrm = np.stack([np.zeros(n), b * np.cos(tt), a * np.sin(tt)], 1)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    # Taper the width toward the ends (a typical cuff outline).
    taper = 0.75 + 0.25 * np.sin(np.pi * np.arange(n) / (n - 1))
    base = rounded_rect2d(0.0, t, w / 2, 24, power=5.0)
    prof = np.repeat(base[None], n, 0)
    prof[..., 1] *= taper[:, None]
    return sweep(path, nrm, np.tile(X, (n, 1)), prof, closed=False)


def _beads(a: float, b: float, params: dict):
    """Beads (spheroids with a bore) threaded on a round cord; bead k takes colour band k of the stripes tile.

    The cord runs bead_radius outside the bore so the beads' inner side just clears it; each straight bead's hole
    (cord radius + 0.5 mm) leaves room for the cord's curvature inside it.
    """
    R = float(params["bead_diameter"]) / 2
    rc = float(params.get("cord_radius", 0.0006))
    hole = rc + 0.0005
    n_colors = len(params["bead_colors"])
    n = samples_for(offset_perimeter(a, b, R), 0.001, 96)
    nrm_c = ellipse_normals(a, b, n)
    cord = sweep(ellipse(a, b, n) + R * nrm_c, nrm_c, np.tile(X, (n, 1)), circle2d(rc, 10))
    parts = [cord.with_uv(slot=0)]
    length = 2 * R * float(params.get("bead_length", 0.9))
    # Straight beads on a curved cord close up on the inner side: widen the spacing by what the sharpest bend
    # (radius rho at the ellipse's ends) takes away there, length * R / rho.
    rho = min(a, b) ** 2 / max(a, b) + R
    spacing = float(params.get("bead_spacing", 0.0004)) + length * R / rho
    count = int(offset_perimeter(a, b, R) // (length + spacing))
    pts, tan, nrm = arc_length_frames(a, b, count, R)
    m = 24
    prof = superellipse2d((R - hole) / 2, length / 2, 16, power=float(params.get("bead_power", 2.0)))
    prof = prof + [(R + hole) / 2, 0.0]
    for k in range(count):
        # A bead is a profile revolved about the cord tangent: sweep around a circle in the plane normal to it.
        u = nrm[k]
        v = np.cross(tan[k], u)
        ang = 2 * np.pi * np.arange(m) / m
        ring_dirs = np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * v
        path = np.tile(pts[k], (m, 1))
        n2 = np.tile(tan[k], (m, 1))
        bead = sweep(path, ring_dirs, n2, prof)
        band_k = k % n_colors
        parts.append(bead.with_uv(slot=1, uv_rect=(0.1, 1 - (band_k + 0.8) / n_colors, 0.9,
                                                   1 - (band_k + 0.2) / n_colors)))
    return parts


def _charms(a: float, b: float, wire: float, params: dict, rng: np.random.Generator):
    """Flat charms (disc, heart, star) lying on the outside of the chain, facing outward."""
    shapes = params.get("charms", ["heart", "disc", "star"])
    size = float(params.get("charm_size", 0.009))
    thick = float(params.get("charm_thickness", 0.0012))
    H = 3.3 * wire
    outside = 2 * H + 2 * wire + GAP                   # beyond the standing links' outer wire
    count = len(shapes)
    spread = float(params.get("charm_spread", 0.9))      # radians of the ellipse covered, centred on the top
    tt = np.linspace(-spread, spread, count) if count > 1 else np.zeros(1)
    parts = []
    for shape, t0 in zip(shapes, tt):
        p = np.array([0.0, a * np.cos(t0), b * np.sin(t0)])
        nrm = np.array([0.0, b * np.cos(t0), a * np.sin(t0)])
        nrm /= np.linalg.norm(nrm)
        tan = np.cross(nrm, X)
        fp = {"disc": circle2d(size / 2, 32), "heart": heart2d(size / 2, 48), "star": star2d(size / 2)}[shape]
        solid = stacked_solid(fp, [0.0, thick], [1.0, 1.0], side_slot=1)
        # Footprint x along the forearm, y around the wrist; its thickness along X x tan = outward.
        parts += place(solid, p + outside * nrm, X, -tan if np.dot(np.cross(X, -tan), nrm) > 0 else tan)
    return parts
