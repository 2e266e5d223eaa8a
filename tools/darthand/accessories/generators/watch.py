"""Wrist watches: a round or square case with a textured dial, lugs, a crown, and a strap of leather, fabric or
metal links.

Local frame: the forearm axis along +X (toward the elbow), the strap's bore the ellipse (inner_a along +Y, inner_b
along Z) in the plane x = 0, the case on the dorsal side (+Y). The dial reads with 12 o'clock toward +Z and
3 o'clock toward -X (the fingers) when seen from +Y. Atlas slots: 0 case metal, 1 dial, 2 strap.
"""

from __future__ import annotations

import numpy as np

from darthand.accessories import textures as tx
from darthand.accessories.generators.shapes import arc_length_frames, band, place, rounded_box
from darthand.accessories.mesh import (AccessoryMesh, circle2d, combine, ellipse, ellipse_normals, ellipse_perimeter,
                                       rounded_rect2d, stacked_solid, superellipse2d, sweep)

STRAPS = ("leather", "fabric", "metal")
CASES = ("round", "square")
GAP = 0.0002
X, Y, Z = np.eye(3)


def watch(params: dict, rng: np.random.Generator, texture_size: int = 512) -> AccessoryMesh:
    """A watch on the bore (params["inner_a"], params["inner_b"]) with params: case ("round"/"square"),
    case_size (diameter or side, m), case_height, strap ("leather"/"fabric"/"metal"), strap_width,
    strap_thickness, metal, dial/marker/hands colours, strap colours."""
    a, b = float(params["inner_a"]), float(params["inner_b"])
    sw, st = float(params["strap_width"]), float(params["strap_thickness"])
    parts = _strap(a, b, sw, st, params["strap"])
    top = a + st                                   # strap's outer surface on the dorsal crest
    parts += _case(params, top + GAP)
    parts += _lugs(a, b, st, sw, params)
    parts += _crown(params, top + GAP)
    verts, faces, uvs, fuv = combine(parts)
    half = texture_size // 2
    metal = tx.METALS[params["metal"]]
    tiles = {0: tx.metal(metal, rng, half, roughness=float(params.get("roughness", 0.25))),
             1: tx.dial(params.get("dial_color", (0.9, 0.9, 0.88)), params.get("marker_color", (0.05, 0.05, 0.05)),
                        params.get("hands_color", (0.05, 0.05, 0.06)), rng, half)}
    strap_color = params.get("strap_color", (0.2, 0.08, 0.03))
    if params["strap"] == "leather":
        tiles[2] = tx.leather(strap_color, rng, half)
    elif params["strap"] == "fabric":
        tiles[2] = tx.fabric(strap_color, params.get("strap_color2", (0.6, 0.6, 0.6)), rng, half)
    else:
        tiles[2] = tiles[0]
    dims = {"inner_a": a, "inner_b": b, "inner_circumference": ellipse_perimeter(a, b), "strap_width": sw,
            "strap_thickness": st, "case_size": float(params["case_size"]),
            "case_height": float(params["case_height"]), "width": float(np.ptp(verts[:, 0]))}
    material = {"kind": "watch", "metal": params["metal"], "strap": params["strap"], "base_color": list(metal),
                "metallic": 1.0, "roughness": float(params.get("roughness", 0.25))}
    return AccessoryMesh(verts, faces, uvs, fuv, material, tx.atlas(tiles, texture_size), dims, len(parts))


def _strap(a: float, b: float, sw: float, st: float, kind: str):
    if kind in ("leather", "fabric"):
        prof = rounded_rect2d(0.0, st, sw / 2, 24, power=6.0 if kind == "leather" else 10.0)
        return [band(a, b, prof).with_uv(slot=2)]
    # Metal bracelet: rounded box links tangent to the bore, one centred under the case (t = 0).
    pitch_target = 0.006
    count = max(8, int(round(ellipse_perimeter(a, b) / pitch_target)))
    pts, tan, nrm = arc_length_frames(a, b, count)
    pitch = ellipse_perimeter(a, b) / count
    parts = []
    for i in range(count):
        link = rounded_box(pitch / 2 - GAP, sw / 2, 0.0, st, power=6.0, slot=2)
        # Footprint x along the tangent, y along the forearm; height along the outward normal.
        x_axis, y_axis = tan[i], X
        parts += place(link, pts[i], x_axis, y_axis) if np.dot(np.cross(x_axis, y_axis), nrm[i]) > 0 \
            else place(link, pts[i], x_axis, -y_axis)
    return parts


def _case_footprint(params: dict, m: int = 64) -> np.ndarray:
    s = float(params["case_size"]) / 2
    if params["case"] == "round":
        return circle2d(s, m)
    return superellipse2d(s, s * float(params.get("case_aspect", 1.15)), m, power=5.0)


def _case(params: dict, base: float):
    """The case: a bevelled solid whose flat top is the dial (footprint x -> -X (3 o'clock), y -> +Z (12))."""
    h = float(params["case_height"])
    fp = _case_footprint(params)
    solid = stacked_solid(fp, [0.0, 0.2 * h, 0.75 * h, 0.85 * h, h], [0.9, 1.0, 1.0, 0.93, 0.88], side_slot=0,
                          cap_slot=1)
    return place(solid, [0, base, 0], -X, Z)


def _lugs(a: float, b: float, st: float, sw: float, params: dict):
    """Two curved bars per side (12 and 6 o'clock) lying on the strap from under the case edge outward."""
    lug_h, lug_w, lug_len = 0.0012, 0.0014, 0.0045
    base = st + GAP
    n = 256
    path = ellipse(a, b, n)
    nrm = ellipse_normals(a, b, n)
    outer = path + base * nrm                          # where the lug's underside runs
    drop = (a + base) - outer[:, 1]                    # how far the strap has fallen below the case's underside
    parts = []
    for side in (+1, -1):
        cand = np.where((np.sign(outer[:, 2]) == side) & (outer[:, 1] > 0) & (drop > lug_h + 2 * GAP))[0]
        if len(cand) == 0:
            continue
        # From where the strap has fallen far enough for the bar to pass under the case, run lug_len along it.
        z0 = np.abs(outer[cand, 2]).min()
        ok = np.sort(cand[np.abs(outer[cand, 2]) <= z0 + lug_len])
        if len(ok) < 3:
            continue
        for x in (sw / 2 - lug_w / 2 - 0.0005, -(sw / 2 - lug_w / 2 - 0.0005)):
            p = outer[ok] + [x, 0, 0]
            prof = rounded_rect2d(0.0, lug_h, lug_w / 2, 12, power=4.0)
            parts.append(sweep(p, nrm[ok], np.tile(X, (len(ok), 1)), prof, closed=False))
    return parts


def _crown(params: dict, base: float):
    """A short knurled cylinder at 3 o'clock (toward -X), at mid-height of the case."""
    fp = _case_footprint(params)
    reach = float(np.abs(fp[:, 0]).max())
    h = float(params["case_height"])
    r, length = 0.1 * h + 0.0008, 0.0022
    crown = stacked_solid(circle2d(r, 16), [0.0, length], [1.0, 1.0], side_slot=0)
    # Footprint in (Z, Y), height along Z x Y = -X.
    return place(crown, [-(reach + GAP), base + 0.5 * h, 0], Z, Y)
