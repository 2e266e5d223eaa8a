"""Skin bases: the plausible albedo every variant starts from, and the base-variation categories.

The base is never a flat colour: palms and palmar fingers carry less melanin and more blood than the back,
knuckles and fingertips are redder (and knuckles darker on darker skin, with fine folds), skin around the nails is
pinker, nail beds are pink with a pale lunula and a whitish free edge, and three bands of solid noise give
mottling, blotchiness and pores. No lighting is baked in: there is no shading term anywhere.

Base-variation categories (freckles, veins, age spots, redness, tan, dry skin, vitiligo) each have
`sample_<name>(rng, spec) -> params` (JSON-able, drawn from the catalogue's ranges) and
`apply_<name>(canvas, surface, params, rng)`.
"""

from __future__ import annotations

import numpy as np

from darthand.textures import color
from darthand.textures.canvas import Canvas
from darthand.textures.noise import smoothstep
from darthand.textures.sampling import draw
from darthand.textures.surface import Surface

NAIL_ROUGHNESS = 0.3


# ---------------------------------------------------------------------------------------------- base skin
def sample_base(rng: np.random.Generator, spec: dict, index: int = 0) -> dict:
    """Base skin parameters from the catalogue's `skin` ranges."""
    return {name: draw(rng, spec[name]) for name in sorted(spec)}


def apply_base(canvas: Canvas, surface: Surface, p: dict, rng: np.random.Generator) -> None:
    """Paint the base skin of a variant onto `canvas` (pigments everywhere, nail beds as a paint layer)."""
    b = canvas.bake
    m0, s = canvas.melanin, canvas.pigment_scale
    palmar, wrist = canvas.field("palmar"), canvas.field("wrist")
    knuckle, tip, cuticle = canvas.field("knuckle"), canvas.field("tip"), canvas.field("cuticle")
    low, low2 = b.noise("low", rng), b.noise("low", rng)
    mid, mid2 = b.noise("mid", rng), b.noise("mid", rng)
    fine = b.noise("fine", rng)
    pore = b.noise("pore", rng)

    # Palm side: less melanin (strongly so on dark skin), more blood; the inner wrist only partly.
    side = smoothstep(0.05, 0.95, palmar + 0.5 * mid * palmar * (1.0 - palmar))  # irregular only at the edge
    lift = side * (1.0 - 0.4 * wrist)
    canvas.dm -= lift * (p["palm_lift"] * m0 + 0.12)
    canvas.dh += lift * p["palm_blood"] * (1.0 + 0.35 * low2)
    # Back of the forearm a touch darker than the back of the hand.
    canvas.dm += (1.0 - side) * wrist * 0.08 * m0
    # Knuckles: redder; darker on darker skin; fine folds.
    canvas.dh += knuckle * p["knuckle_blood"]
    canvas.dm += knuckle * (1.0 - side) * p["knuckle_pigment"] * m0
    wrinkle = canvas.field("wrinkle") * smoothstep(-0.6, 0.8, fine)
    canvas.dm += wrinkle * (0.35 * s) * p["wrinkles"]
    canvas.dh += wrinkle * 0.08 * p["wrinkles"]
    # Fingertips and the skin around the nails: redder.
    canvas.dh += tip * p["tip_blood"] + cuticle * 0.22
    canvas.dm += cuticle * 0.12 * m0
    # Mottling (melanin), blotchiness (blood), pores; melanin texture scales with the local melanin, so a
    # dark hand's lighter palm is not covered in dark blotches.
    local = np.float32(0.015) + np.float32(0.012) * np.maximum(m0 + canvas.dm, np.float32(0.0))
    canvas.dm += p["mottle"] * local * (0.8 * low + 1.0 * mid + 0.7 * fine)
    canvas.dh += p["mottle"] * (0.035 * low2 + 0.025 * mid2)
    canvas.dm += p["pores"] * local * 0.7 * pore
    # Faint superficial veins on the back of the hand and the inner wrist.
    if p["veins"] > 0:
        apply_veins(canvas, surface, {"strength": p["veins"]}, rng)
    apply_nail_beds(canvas, p, fine)


def apply_nail_beds(canvas: Canvas, p: dict, fine: np.ndarray) -> None:
    """Nail texels: a pink bed (blood showing through, little melanin) with a pale lunula at the fold and a
    whitish free edge; faint lengthwise ridges."""
    b = canvas.bake
    idx = np.nonzero(b.fields["nail"] > 0)[0]
    if not len(idx):
        return
    cover = b.fields["nail"][idx].astype(np.float32)
    u, v = b.fields["nail_u"][idx].astype(np.float32), b.fields["nail_v"][idx].astype(np.float32)
    dm = np.full(len(idx), -0.75 * canvas.melanin - 0.1, np.float32)
    dh = (p["nail_blood"] * (1.0 - 0.5 * smoothstep(0.55, 0.9, u)) + 0.05 * fine[idx]).astype(np.float32)
    bed = color.pigment_albedo(canvas.tone_rgb, dm, dh, np.zeros_like(dm))
    ridges = 1.0 + 0.025 * np.cos(v * np.float32(9.0 * np.pi)) + 0.015 * fine[idx]
    bed *= ridges[:, None]
    lunula = (1.0 - smoothstep(0.7, 1.0, np.hypot(u / 0.24, v / 0.78))) * p["lunula"]
    free_edge = smoothstep(0.86, 0.95, u)
    pale = np.array([0.78, 0.72, 0.68], np.float32)
    edge = np.array([0.80, 0.77, 0.72], np.float32)
    rgb = bed * (1 - lunula)[:, None] + pale * lunula[:, None]
    rgb = rgb * (1 - free_edge)[:, None] + edge * free_edge[:, None]
    canvas.paint(idx, rgb, cover, roughness=NAIL_ROUGHNESS)


# --------------------------------------------------------------------------------- base variations
def sample_freckles(rng, spec, index=0):
    return {"count": int(draw(rng, spec["count_range"], integer=True)), "diameter_mm": draw(rng, spec["diameter_mm"]),
            "strength": draw(rng, spec["strength"]), "clustering": draw(rng, spec["clustering"])}


def apply_freckles(canvas: Canvas, surface: Surface, p: dict, rng) -> None:
    """Many small melanin spots on the back of the hand, fingers and forearm, clustered by low noise."""
    dorsal_only = lambda c, n: np.clip(n @ [0.0, 1.0, 0.0] + 0.3, 0, 1)  # noqa: E731
    pts, _ = surface.sample_points(rng, p["count"], {"dorsum": 1.0, "finger_dorsal": 0.5, "wrist": 0.8,
                                                     "finger_palmar": 0.05}, where=dorsal_only)
    radius = 0.5e-3 * p["diameter_mm"] * rng.uniform(0.5, 1.4, len(pts))
    strength = p["strength"] * rng.uniform(0.4, 1.0, len(pts))
    keep = rng.random(len(pts)) < 0.35 + 0.65 * _cluster(canvas, surface, pts, p["clustering"])
    spots(canvas, surface, pts[keep], radius[keep], strength[keep] * canvas.pigment_scale, softness=0.6)


def _cluster(canvas, surface, pts, clustering):
    """Acceptance probability (K,) for spots at `pts`: low noise at the nearest texel, sharpened by clustering."""
    _, near = surface.tree.query(pts)
    low = canvas.bake.fields["noise_low0"][near].astype(np.float32)
    return smoothstep(-clustering, clustering, low)


def spots(canvas: Canvas, surface: Surface, centres, radii, melanin, softness=0.5, irregular=0.0,
           blood=None) -> None:
    """Add round-ish melanin spots: dm += melanin_k * profile(distance / radius_k), max over overlapping spots."""
    if len(centres) == 0:
        return
    idx, k = surface.balls(centres, float(np.max(radii)) * (1.0 + irregular) + 1e-5)
    pos = canvas.bake.position[idx]
    d = np.linalg.norm(pos - centres[k].astype(np.float32), axis=1) / radii[k]
    if irregular:
        d = d * (1.0 + irregular * canvas.bake.fields["noise_fine0"][idx].astype(np.float32) * 0.5)
    prof = (1.0 - smoothstep(1.0 - softness, 1.0, d)).astype(np.float32)
    val = np.zeros(canvas.n, np.float32)
    np.maximum.at(val, idx, prof * np.asarray(melanin, np.float32)[k])
    canvas.dm += val
    if blood is not None:
        bval = np.zeros(canvas.n, np.float32)
        np.maximum.at(bval, idx, prof * np.asarray(blood, np.float32)[k])
        canvas.dh += bval


def sample_veins(rng, spec, index=0):
    return {"strength": draw(rng, spec["strength"])}


def apply_veins(canvas: Canvas, surface: Surface, p: dict, rng) -> None:
    """Superficial veins (one of the bake's vein layouts) on the back of the hand, the forearm and the inner
    wrist, bluish through the skin; fainter on darker skin (more melanin hides them), never over knuckles."""
    b = canvas.bake
    count = sum(1 for k in b.fields if k.startswith("veins"))
    veins = b.fields[f"veins{int(rng.integers(count))}"]
    fade = smoothstep(-1.5, 0.5, b.noise("mid", rng))  # veins sink out of sight here and there
    visibility = p["strength"] / (1.0 + 0.5 * canvas.melanin)
    amount = veins * fade * (1.0 - canvas.field("knuckle")) * np.float32(visibility)
    canvas.dv += amount
    canvas.dm -= amount * np.float32(0.2 * canvas.melanin)


def sample_age_spots(rng, spec, index=0):
    return {"count": int(draw(rng, spec["count_range"], integer=True)), "diameter_mm": draw(rng, spec["diameter_mm"]),
            "strength": draw(rng, spec["strength"])}


def apply_age_spots(canvas: Canvas, surface: Surface, p: dict, rng) -> None:
    """Solar lentigines: irregular flat brown macules, 3-10 mm, on the back of the hand and forearm."""
    dorsal_only = lambda c, n: np.clip(n @ [0.0, 1.0, 0.0] + 0.2, 0, 1)  # noqa: E731
    pts, _ = surface.sample_points(rng, p["count"], {"dorsum": 1.0, "wrist": 0.7, "finger_dorsal": 0.25},
                                   where=dorsal_only)
    radius = 0.5e-3 * p["diameter_mm"] * rng.uniform(0.5, 1.3, len(pts))
    strength = p["strength"] * rng.uniform(0.5, 1.0, len(pts)) * canvas.pigment_scale
    spots(canvas, surface, pts, radius, strength, softness=0.45, irregular=0.6)
    canvas.dm += 0.04 * canvas.pigment_scale * canvas.bake.noise("mid", rng) * (1 - canvas.field("palmar"))


def sample_redness(rng, spec, index=0):
    return {"strength": draw(rng, spec["strength"]), "pattern": draw(rng, spec["patterns"])}


def apply_redness(canvas: Canvas, surface: Surface, p: dict, rng) -> None:
    """Erythema: blotchy redness on the back ('blotchy'), cold red fingers ('fingers'), or red knuckles and
    palms ('flushed')."""
    b = canvas.bake
    blotch = smoothstep(-0.6, 1.2, b.noise("low", rng) + 0.5 * b.noise("mid", rng))
    s = p["strength"]
    if p["pattern"] == "blotchy":
        canvas.dh += s * blotch * (1 - 0.5 * canvas.field("palmar"))
    elif p["pattern"] == "fingers":
        distal = np.isin(b.fields["bone"], [1, 2, 4, 5, 7, 8, 10, 11, 13, 14]).astype(np.float32)
        canvas.dh += s * (0.6 * distal + 0.8 * canvas.field("tip")) * (0.6 + 0.4 * blotch)
    else:
        canvas.dh += s * (0.9 * canvas.field("knuckle") + 0.5 * canvas.field("palmar") * blotch + 0.2 * blotch)


def sample_tan(rng, spec, index=0):
    return {"strength": draw(rng, spec["strength"]), "strap_line": bool(rng.random() < spec["strap_probability"]),
            "strap_width_mm": draw(rng, spec["strap_width_mm"])}


def apply_tan(canvas: Canvas, surface: Surface, p: dict, rng) -> None:
    """Sun tan on the back of the hand and forearm (more melanin where the sun reaches), optionally with the
    pale band of a watch strap at the wrist."""
    back = 1.0 - smoothstep(0.2, 0.8, canvas.field("palmar"))
    tan = p["strength"] * (0.25 + 0.5 * canvas.melanin) * back
    if p["strap_line"]:
        x = canvas.bake.position[:, 0] - surface.joints[0, 0]
        half = 0.5e-3 * p["strap_width_mm"]
        centre = 0.012 + half
        band = 1.0 - smoothstep(half - 0.0012, half + 0.0012, np.abs(x - centre))
        tan = tan * (1.0 - 0.85 * band)
    canvas.dm += tan
    canvas.dh += 0.05 * back * p["strength"]


def sample_dry_skin(rng, spec, index=0):
    return {"strength": draw(rng, spec["strength"]), "cracks": draw(rng, spec["cracks"])}


def apply_dry_skin(canvas: Canvas, surface: Surface, p: dict, rng) -> None:
    """Ashy dry skin: a thin whitish-grey scale layer, strongest over the knuckles and the back of the hand,
    with the knuckle folds picked out (reads most on darker skin, as it does in life)."""
    b = canvas.bake
    back = 1.0 - canvas.field("palmar")
    knuckle, wrist = canvas.field("knuckle"), canvas.field("wrist")
    film = (0.08 + 0.17 * knuckle + 0.05 * wrist) * (0.6 + 0.4 * smoothstep(-1.5, 1.5, b.noise("low", rng)))
    flakes = 0.08 * smoothstep(0.8, 2.5, b.noise("fine", rng))
    lines = 0.25 * canvas.field("wrinkle") * p["cracks"]
    alpha = np.clip(p["strength"] * back * (film + flakes) + lines * back, 0.0, 0.35)
    idx = np.nonzero(alpha > 0.005)[0]
    canvas.paint(idx, np.array([0.56, 0.53, 0.50], np.float32), alpha[idx], roughness=0.7)


def sample_vitiligo(rng, spec, index=0):
    return {"coverage": draw(rng, spec["coverage"]), "sites": draw(rng, spec["sites"])}


def apply_vitiligo(canvas: Canvas, surface: Surface, p: dict, rng) -> None:
    """Depigmented patches with sharp but irregular borders, favouring fingers, knuckles and the wrist."""
    b = canvas.bake
    field = b.noise("low", rng) + 0.45 * b.noise("mid", rng)
    bias = {"fingers": 0.9 * (b.fields["finger"] >= 0) * (b.fields["bone"] < 15),
            "knuckles": 1.6 * canvas.field("knuckle") + 0.5 * canvas.field("tip"),
            "wrist": 1.2 * canvas.field("wrist")}[p["sites"]]
    threshold = np.float32(1.6 - 2.2 * p["coverage"])
    patch = smoothstep(threshold - 0.08, threshold + 0.08, field + bias)
    canvas.dm -= patch * (0.88 * canvas.melanin + 0.05)  # depigmented skin stays ivory-pink, not white
    canvas.dh += patch * 0.12
    rim = smoothstep(threshold - 0.35, threshold - 0.08, field + bias) * (1 - patch)
    canvas.dm += rim * 0.12 * canvas.melanin


BASE_VARIATIONS = {
    "freckles": (sample_freckles, apply_freckles),
    "veins": (sample_veins, apply_veins),
    "age_spots": (sample_age_spots, apply_age_spots),
    "redness": (sample_redness, apply_redness),
    "tan": (sample_tan, apply_tan),
    "dry_skin": (sample_dry_skin, apply_dry_skin),
    "vitiligo": (sample_vitiligo, apply_vitiligo),
}
