"""Overlay categories: bandage, palm prints, scars, tattoos, moles, nail colours.

Each category has `sample_<name>(rng, spec, index) -> params` (JSON-able, drawn from the catalogue spec's ranges;
`index` is the entry's number within its tone so that styles can be cycled) and
`apply_<name>(canvas, surface, params, rng)`. Overlays are placed on the surface (anatomical sites, bones,
3D positions), never in UV space.
"""

from __future__ import annotations

import numpy as np

from darthand.model.layout import FACE_LABEL_IDS, FINGERS
from darthand.textures import color
from darthand.textures.canvas import Canvas
from darthand.textures.curves import bezier, curve_distance
from darthand.textures.motifs import BAND_MOTIFS, BAND_PERIOD, MOTIFS, rotate, segment
from darthand.textures.noise import smoothstep
from darthand.model.regions import FOREARM_AXIS, PALM_NORMAL, hand_frame
from darthand.textures.sampling import draw
from darthand.textures.skin import spots
from darthand.textures.surface import Frame, Surface

MM = 1e-3


def _lin(srgb) -> np.ndarray:
    """sRGB (3,) in [0, 1] -> linear float32."""
    return color.srgb_to_linear(np.asarray(srgb, np.float32))


def _site(rng, spec_sites) -> dict:
    """A placement: site name and its along/across/finger/level parameters."""
    site = draw(rng, spec_sites)
    out = {"site": site, "along": round(float(rng.uniform(0.25, 0.8)), 5),
           "across": round(float(rng.uniform(-0.7, 0.7)), 5)}
    if site == "finger":
        out["finger"] = draw(rng, ["index", "middle", "ring", "pinky", "thumb"])
        out["level"] = int(rng.integers(0, 2))
    return out


def _frame(surface: Surface, place: dict) -> Frame:
    return surface.site(place["site"], along=place["along"], across=place["across"],
                        finger=place.get("finger", "middle"), level=place.get("level", 0))


def _fine(canvas: Canvas, idx, band="fine", k=0) -> np.ndarray:
    return canvas.bake.fields[f"noise_{band}{k}"][idx].astype(np.float32)


# ------------------------------------------------------------------------------------------------ bandage
BANDAGE_STYLES = ("gauze_finger", "palm_wrap", "adhesive_strip", "wrist_wrap", "buddy_tape")


def sample_bandage(rng, spec, index):
    style = BANDAGE_STYLES[index % len(BANDAGE_STYLES)]
    p = {"style": style, "tint": draw(rng, spec["tint"]), "soiling": draw(rng, spec["soiling"])}
    if style in ("gauze_finger", "adhesive_strip"):
        p["finger"] = draw(rng, ["index", "middle", "ring", "pinky", "thumb"])
        p["level"] = int(rng.integers(0, 2))
        p["width_mm"] = draw(rng, spec["finger_width_mm"])
        p["pad_side"] = draw(rng, ["dorsal", "palmar"])
    elif style == "buddy_tape":
        pair = int(rng.integers(0, 3))
        p["fingers"] = [("index", "middle", "ring", "pinky")[pair], ("index", "middle", "ring", "pinky")[pair + 1]]
        p["level"] = int(rng.integers(0, 2))
        p["width_mm"] = draw(rng, spec["tape_width_mm"])
    else:
        p["width_mm"] = draw(rng, spec["wrap_width_mm"])
        p["start"] = draw(rng, [0.1, 0.35]) if style == "palm_wrap" else draw(rng, [0.0, 0.15])
    return p


def apply_bandage(canvas: Canvas, surface: Surface, p: dict, rng) -> None:
    {"gauze_finger": _gauze_finger, "palm_wrap": _palm_wrap, "adhesive_strip": _adhesive_strip,
     "wrist_wrap": _wrist_wrap, "buddy_tape": _buddy_tape}[p["style"]](canvas, surface, p, rng)


def _finger_band(canvas, surface, finger, level, width, along=0.5):
    """Texels of a band around `finger`'s segment `level`, centred `along` it: index, axial offset from the band
    centre (m), angle around (rad, 0 at the back), radius (m)."""
    chain = surface.chain(finger)
    start, end = chain[level], chain[level + 1]
    bones = [FINGERS.index(finger) * 3 + k for k in range(3)]
    idx = surface.texels_of_bones(bones)
    a, ang, r = surface.cylinder(start, end, -PALM_NORMAL, idx)
    a = a - along * np.linalg.norm(end - start)
    keep = np.abs(a) <= 0.5 * width + 0.001
    return idx[keep], a[keep], ang[keep], r[keep]


def _turns(ang, radius, period):
    """Angle around an axis (rad) -> a coordinate in units of `period` (metres at `radius`), rounded so a whole
    number of periods fits around: patterns built on it close up seamlessly where the angle wraps."""
    count = max(1, int(round(2 * np.pi * radius / period)))
    return ang * (count / (2 * np.pi))


def _weave(a, ang, radius, period):
    """Gauze around a cylinder: threads along and around it (about `period` metres apart); 1 on a thread, 0 in
    the holes."""
    warp = np.cos(np.pi * a / period) ** 2
    weft = np.cos(np.pi * _turns(ang, radius, period)) ** 2
    return np.clip(np.maximum(warp, weft) ** 0.5, 0, 1).astype(np.float32)


def _fabric(canvas, idx, base_rgb, tint, soiling, texture):
    """Colour of a fabric layer: base colour modulated by its weave texture, tinted and soiled."""
    dirt = soiling * smoothstep(-0.5, 1.5, _fine(canvas, idx, "mid", 1))
    rgb = np.asarray(base_rgb, np.float32) * (1.0 - tint * np.array([0.0, 0.06, 0.15], np.float32))
    rgb = rgb[None] * (0.82 + 0.18 * texture)[:, None]
    return rgb * (1.0 - 0.35 * dirt)[:, None] + np.array([0.30, 0.24, 0.16], np.float32) * (0.35 * dirt)[:, None]


def _edge_alpha(a, half_width, canvas, idx, fray=0.4 * MM):
    edge = half_width + fray * _fine(canvas, idx)
    return (1.0 - smoothstep(edge - 0.25 * MM, edge + 0.25 * MM, np.abs(a))).astype(np.float32)


def _gauze_finger(canvas, surface, p, rng):
    w = p["width_mm"] * MM
    idx, a, ang, r = _finger_band(canvas, surface, p["finger"], p["level"], w)
    radius = float(np.median(r)) if len(r) else 0.008
    threads = _weave(a, ang, radius, 0.9 * MM)
    layers = 0.5 + 0.5 * np.cos(2 * np.pi * a / (0.45 * w) + ang)  # the wraps' helix
    rgb = _fabric(canvas, idx, [0.84, 0.83, 0.80], p["tint"], p["soiling"], 0.7 * threads + 0.3 * layers)
    alpha = _edge_alpha(a, 0.5 * w, canvas, idx) * (0.80 + 0.2 * threads)
    canvas.paint(idx, rgb, alpha, roughness=0.9)


def _adhesive_strip(canvas, surface, p, rng):
    w = p["width_mm"] * MM
    idx, a, ang, r = _finger_band(canvas, surface, p["finger"], p["level"], w)
    radius = float(np.median(r)) if len(r) else 0.008
    plastic = _lin([0.80, 0.62, 0.47]) * (1.0 - 0.1 * p["tint"])
    holes = (np.cos(2 * np.pi * a / (1.3 * MM)) * np.cos(2 * np.pi * _turns(ang, radius, 1.3 * MM)) > 0.92)
    holes = holes.astype(np.float32)
    rgb = plastic[None] * (1.0 - 0.12 * holes)[:, None]
    pad_centre = 0.0 if p["pad_side"] == "dorsal" else np.pi
    pad_arc = np.abs(np.angle(np.exp(1j * (ang - pad_centre)))) * radius
    pad = (1.0 - smoothstep(0.30 * w - 0.3 * MM, 0.30 * w, np.abs(a))) * (1.0 - smoothstep(5.5 * MM, 6 * MM, pad_arc))
    pad_rgb = np.array([0.86, 0.84, 0.80], np.float32) * (0.9 + 0.1 * _weave(a, ang, radius, 0.5 * MM))[:, None]
    rgb = rgb * (1 - pad)[:, None] + pad_rgb * pad[:, None]
    rounded = 1.0 - smoothstep(0.5 * w - 0.3 * MM, 0.5 * w, np.abs(a))
    canvas.paint(idx, rgb, rounded, roughness=0.45)


def _buddy_tape(canvas, surface, p, rng):
    w = p["width_mm"] * MM
    for finger in p["fingers"]:
        idx, a, ang, r = _finger_band(canvas, surface, finger, p["level"], w, along=0.55)
        weave = _weave(a, ang, float(np.median(r)) if len(r) else 0.008, 0.35 * MM)
        rgb = _fabric(canvas, idx, [0.86, 0.86, 0.84], p["tint"], p["soiling"], weave)
        canvas.paint(idx, rgb, _edge_alpha(a, 0.5 * w, canvas, idx, fray=0.15 * MM), roughness=0.8)


def _wrap_region(canvas, surface, x0, x1):
    """Texels of the palm, the thumb's base and the forearm with x between x0 and x1 (a wrap goes over the
    ball of the thumb rather than around it)."""
    idx = surface.texels_of_bones([15, 16, 17, 18, 19, 20, 0])
    x = canvas.bake.position[idx, 0]
    return idx[(x >= x0 - 0.002) & (x <= x1 + 0.002)]


def _crepe(canvas, surface, p, x0, x1, base_rgb):
    idx = _wrap_region(canvas, surface, x0, x1)
    pos = canvas.bake.position[idx].astype(np.float64)
    x = pos[:, 0] - 0.5 * (x0 + x1)
    centre = pos[:, 1:].mean(0)
    around = np.arctan2(pos[:, 2] - centre[1], pos[:, 1] - centre[0])
    crepe = 0.5 + 0.5 * np.cos(2 * np.pi * x / (1.1 * MM))
    layers = 0.5 + 0.5 * np.cos(2 * np.pi * x / (0.3 * (x1 - x0)) + around)  # the wraps' helix
    rgb = _fabric(canvas, idx, base_rgb, p["tint"], p["soiling"], 0.6 * crepe + 0.4 * layers)
    alpha = _edge_alpha(x, 0.5 * (x1 - x0), canvas, idx, fray=0.2 * MM)
    canvas.paint(idx, rgb, alpha, roughness=0.85)


def _palm_wrap(canvas, surface, p, rng):
    wrist_x = surface.joints[0, 0]
    knuckle_x = 0.5 * (surface.joint("index", 0)[0] + surface.joint("pinky", 0)[0])
    x1 = wrist_x + (knuckle_x - wrist_x) * p["start"]
    x0 = x1 - p["width_mm"] * MM
    _crepe(canvas, surface, p, max(x0, knuckle_x + 0.012), x1, _lin([0.93, 0.91, 0.87]))


def _wrist_wrap(canvas, surface, p, rng):
    wrist_x = surface.joints[0, 0]
    extent = float(surface.vertices[:, 0].max() - wrist_x)
    x0 = wrist_x + p["start"] * extent - 0.004
    _crepe(canvas, surface, p, x0, x0 + p["width_mm"] * MM, _lin([0.84, 0.70, 0.55]))


# -------------------------------------------------------------------------------------------- palm prints
def sample_palm_prints(rng, spec, index):
    return {"depth": draw(rng, spec["depth"]), "width_mm": draw(rng, spec["width_mm"]),
            "heart_curve": draw(rng, [-0.12, 0.12]), "head_slope": draw(rng, [-0.15, 0.15]),
            "life_reach": draw(rng, [0.0, 0.25]), "fate_line": bool(rng.random() < spec["fate_probability"]),
            "minor_lines": int(draw(rng, spec["minor_lines"], integer=True)),
            "ridges": draw(rng, spec["ridges"]), "seed_curves": int(rng.integers(0, 2 ** 31))}


def apply_palm_prints(canvas: Canvas, surface: Surface, p: dict, rng) -> None:
    """Flexion creases of the palm (heart, head, life, optional fate line, minor lines, wrist bracelets), the
    creases across the palmar side of every finger joint, and fine papillary ridges on the finger pads."""
    b = canvas.bake
    origin, f_vec, s_vec = hand_frame(surface.skeleton)
    pc = np.random.default_rng(p["seed_curves"])
    to_xz = lambda pts: origin + np.outer(pts[:, 0], f_vec) + np.outer(pts[:, 1], s_vec)  # noqa: E731
    curves = [  # (control points in (f, s), relative depth): heart, head, life, wrist bracelets
        ([(0.97, -1.3), (0.97 + p["heart_curve"], -0.4), (1.03, 0.15), (1.1, 0.42)], 1.0),
        ([(0.93, 1.12), (0.88, 0.5), (0.8 + p["head_slope"], -0.1), (0.7 + p["head_slope"], -0.8)], 0.9),
        ([(0.93, 1.08), (0.65, 0.6 - p["life_reach"]), (0.28, 0.5), (0.02, 0.62)], 1.0),
        ([(-0.02, -1.25), (-0.03, 0.0), (-0.02, 1.25)], 0.5),
        ([(-0.09, -1.2), (-0.1, 0.0), (-0.09, 1.2)], 0.35),
    ]
    if p["fate_line"]:
        curves.append(([(0.05, -0.05), (0.4, 0.05), (0.8, -0.02)], 0.45))
    for _ in range(p["minor_lines"]):
        c = np.array([pc.uniform(0.2, 0.85), pc.uniform(-0.85, 0.6)])
        d = pc.normal(size=2)
        d *= pc.uniform(0.05, 0.15) / np.linalg.norm(d)
        curves.append(([tuple(c - d), tuple(c + 0.3 * d[::-1]), tuple(c + d)], pc.uniform(0.15, 0.35)))
    samples, depth = [], []
    for ctrl, dep in curves:
        pts = to_xz(bezier(np.array(ctrl), 160))
        t = np.linspace(0.0, 1.0, len(pts))
        samples.append(pts)
        depth.append(dep * np.sin(np.pi * t) ** 0.35)  # creases fade out at their ends
    samples, depth = np.concatenate(samples), np.concatenate(depth)
    width = p["width_mm"] * MM
    # The palm's skin runs past the knuckle joints: take the first finger segments' palm side too.
    idx = surface.texels_of_bones([15, 16, 17, 18, 19, 20, 0, 3, 6, 9, 12])
    xz = b.position[idx][:, [0, 2]]
    lo, hi = samples.min(0) - 4 * width, samples.max(0) + 4 * width
    idx = idx[(b.fields["palmar"][idx] > 0.35) & (xz >= lo).all(1) & (xz <= hi).all(1)]
    d, t_index = curve_distance(samples, b.position[idx][:, [0, 2]].astype(np.float64), 4 * width)
    nearest = np.clip(np.rint(t_index * (len(samples) - 1)).astype(int), 0, len(samples) - 1)
    wobble = 1.0 + 0.35 * _fine(canvas, idx)
    broken = smoothstep(-1.2, 0.4, _fine(canvas, idx, "mid", 1))  # creases fade in and out along their length
    prof = np.exp(-(d / (width * wobble)) ** 2).astype(np.float32) * depth[nearest].astype(np.float32) * broken
    _crease(canvas, idx, prof * p["depth"])
    _finger_creases(canvas, surface, p, width)
    _ridges(canvas, surface, p)


def _crease(canvas, idx, strength):
    """Creases read as darker, slightly redder lines (the melanin of the fold's walls, and its shadow: an albedo
    map is all a renderer without displacement has of a fold)."""
    canvas.dm[idx] += strength * np.float32(0.3 + 0.2 * canvas.melanin)
    canvas.dh[idx] += strength * np.float32(0.14)


def _finger_creases(canvas, surface, p, width):
    """Double creases across the palmar side at each finger joint and a single one at the finger base, bowed
    slightly toward the fingertip at the sides."""
    for idx, prof in finger_crease_profiles(canvas.bake, surface, width):
        _crease(canvas, idx, prof * np.float32(0.8 * p["depth"]))


def finger_crease_profiles(b, surface, width: float):
    """Per finger, (texel ids (K,), crease profile (K,) float32 in [0, 1]) of its palmar texels: a single crease at
    the finger's base (the thumb's further along) and double creases at its next two joints, bowed toward the tip
    at the sides, each a Gaussian across `width` (metres); 0 beyond 3 widths. The layout the palm-prints overlay
    draws and the skin relief (render/skin_detail.py) carves."""
    for f, name in enumerate(FINGERS):
        chain = surface.chain(name)
        lengths = [float(np.linalg.norm(chain[k + 1] - chain[k])) for k in range(3)]
        idx = surface.texels_of_bones([f * 3, f * 3 + 1])
        idx = idx[b.fields["palmar"][idx] > 0.3]
        if not len(idx):
            continue
        level = (b.fields["bone"][idx] % 3).astype(int)
        pos = b.position[idx].astype(np.float64)
        axial = np.zeros(len(idx))
        lateral = np.zeros(len(idx))
        for k in range(2):
            sel = level == k
            d = (chain[k + 1] - chain[k]) / lengths[k]
            side = np.cross(d, -PALM_NORMAL)
            side /= np.linalg.norm(side)
            rel = pos[sel] - chain[k]
            axial[sel] = sum(lengths[:k]) + rel @ d
            lateral[sel] = rel @ side
        bend = 6.0 * lateral ** 2
        creases = [(0.33 * lengths[0], 0.0)] if name != "thumb" else [(0.55 * lengths[0], 0.0)]
        creases += [(lengths[0] - 0.4 * MM, 0.7 * MM), (lengths[0] + lengths[1] - 0.3 * MM, 0.6 * MM)]
        prof = np.zeros(len(idx), np.float32)
        for centre, gap in creases:
            for off in ((-0.5 * gap, 0.5 * gap) if gap else (0.0,)):
                near = np.abs(axial - centre - off - bend) < 3 * width
                dd = (axial[near] - centre - off - bend[near]) / (0.8 * width)
                prof[near] = np.maximum(prof[near], np.exp(-dd * dd).astype(np.float32))
        yield idx, prof


def _ridges(canvas, surface, p):
    """Papillary ridges (about 0.45 mm apart) in loops on the distal finger pads; faded out where the texture
    is too coarse to show them (fewer than ~3 texels per ridge)."""
    period = 0.45 * MM
    fade = float(np.clip((period / surface.texel_size - 2.0) / 2.0, 0.0, 1.0))
    if fade <= 0 or p["ridges"] <= 0:
        return
    b = canvas.bake
    for name in FINGERS:
        chain = surface.chain(name)
        idx = surface.texels_of_bones([FINGERS.index(name) * 3 + 2])
        idx = idx[b.fields["palmar"][idx] > 0.2]
        if not len(idx):
            continue
        a, ang, r = surface.cylinder(chain[2], chain[3], -PALM_NORMAL, idx)
        length = np.linalg.norm(chain[3] - chain[2])
        arc = (np.pi - np.abs(ang)) * np.sign(ang) * r
        da, ds = a - 0.55 * length, arc
        radius = np.sqrt((da / 1.4) ** 2 + ds ** 2) + 0.3 * MM * _fine(canvas, idx)
        ridge = (0.5 + 0.5 * np.cos(2 * np.pi * radius / period)).astype(np.float32)
        env = np.exp(-(radius / (0.55 * length)) ** 2).astype(np.float32)
        canvas.dm[idx] += ridge * env * np.float32(0.09 * p["ridges"] * fade * canvas.pigment_scale)


# -------------------------------------------------------------------------------------------------- scars
def sample_scars(rng, spec, index):
    kind = draw(rng, spec["kinds"])
    p = {"kind": kind, "place": _site(rng, spec["sites"]), "length_mm": draw(rng, spec["length_mm"]),
         "width_mm": draw(rng, spec["width_mm"]), "angle": draw(rng, [-1.2, 1.2]),
         "curvature": draw(rng, [-0.25, 0.25]), "freshness": draw(rng, spec["freshness"]),
         "count": int(draw(rng, [4, 14], integer=True)), "stitches": int(draw(rng, [3, 8], integer=True))}
    if kind in ("burn", "pitted") and p["place"]["site"] == "finger":
        p["place"]["site"] = "dorsum"
    if p["place"]["site"] == "finger":
        p["length_mm"] = round(min(p["length_mm"], 18.0), 5)
    return p


def apply_scars(canvas: Canvas, surface: Surface, p: dict, rng) -> None:
    frame = _frame(surface, p["place"])
    {"incision": _incision, "stitched": _incision, "keloid": _incision, "burn": _burn,
     "pitted": _pitted}[p["kind"]](canvas, surface, frame, p, rng)


def _scar_colour(canvas, idx, prof, p, raised=False):
    """Scar tissue: less melanin (pale) with a pigmented rim on darker skin, pink to red while fresh; shinier.
    Strong enough to read in a 512^2 render of the whole hand (about 0.5 mm per pixel)."""
    m0, s = canvas.melanin, canvas.pigment_scale
    if raised:  # keloid: darker and redder
        canvas.dm[idx] += prof * np.float32(0.6 * s)
        canvas.dh[idx] += prof * np.float32(0.35 + 0.45 * p["freshness"])
    else:
        canvas.dm[idx] -= prof * np.float32(0.85 * m0 + 0.25)
        canvas.dh[idx] += prof * np.float32(0.22 + 0.7 * p["freshness"])
    canvas.roughness[idx] = canvas.roughness[idx] * (1 - 0.4 * prof) + 0.33 * 0.4 * prof


def _incision(canvas, surface, frame, p, rng):
    length, width = p["length_mm"] * MM, p["width_mm"] * MM * (1.8 if p["kind"] == "keloid" else 1.0)
    ctrl = np.array([(-0.5, 0.0), (-0.15, p["curvature"]), (0.15, -0.6 * p["curvature"]), (0.5, 0.1 * p["curvature"])])
    curve = rotate(bezier(ctrl * length, 240), -p["angle"])
    idx, uv = surface.decal(frame, 0.55 * length + 3 * width, facing=0.3)
    d, t = curve_distance(curve, uv, 3 * width)
    taper = np.sin(np.pi * np.clip(t, 0, 1)) ** 0.4
    half = 0.5 * width * taper * (1.0 + 0.3 * _fine(canvas, idx))
    prof = (1.0 - smoothstep(0.55, 1.0, d / np.maximum(half, 1e-5))).astype(np.float32)
    _scar_colour(canvas, idx, prof, p, raised=p["kind"] == "keloid")
    rim = (smoothstep(0.8, 1.2, d / np.maximum(half, 1e-5)) * (1.0 - smoothstep(1.2, 2.2, d / np.maximum(half, 1e-5))))
    canvas.dm[idx] += rim.astype(np.float32) * np.float32(0.3 * canvas.melanin)
    if p["kind"] == "stitched":
        _stitches(canvas, idx, uv, curve, p, width)


def _stitches(canvas, idx, uv, curve, p, width):
    """Suture marks: short dashes across the scar with puncture dots at their ends."""
    n = p["stitches"]
    ts = (np.arange(n) + 0.5) / n
    dash = np.full(len(idx), np.inf)
    dots = np.full(len(idx), np.inf)
    for t in ts:
        k = int(t * (len(curve) - 1))
        c = curve[k]
        tangent = curve[min(k + 1, len(curve) - 1)] - curve[max(k - 1, 0)]
        normal = np.array([-tangent[1], tangent[0]]) / np.linalg.norm(tangent)
        half = 1.6 * MM + width
        a, b = c - half * normal, c + half * normal
        dash = np.minimum(dash, segment(uv, a, b, 0.0))
        dots = np.minimum(dots, np.minimum(np.linalg.norm(uv - a, axis=1), np.linalg.norm(uv - b, axis=1)))
    dash_prof = np.exp(-(dash / (0.22 * MM)) ** 2).astype(np.float32)
    dot_prof = np.exp(-(dots / (0.3 * MM)) ** 2).astype(np.float32)
    canvas.dm[idx] -= dash_prof * np.float32(0.4 * canvas.melanin)
    canvas.dh[idx] += dash_prof * np.float32(0.25) + dot_prof * np.float32(0.3)
    canvas.dm[idx] += dot_prof * np.float32(0.25 * canvas.pigment_scale)


def _burn(canvas, surface, frame, p, rng):
    radius = 0.5 * p["length_mm"] * MM
    idx, uv = surface.decal(frame, 1.5 * radius, facing=0.2)
    q = rotate(uv, -p["angle"]) / [radius, 0.7 * radius]
    shape = np.linalg.norm(q, axis=1) - 1.0 + 0.45 * _fine(canvas, idx, "mid", 2)
    prof = (1.0 - smoothstep(-0.12, 0.05, shape)).astype(np.float32)
    mottle = _fine(canvas, idx, "mid", 3) + 0.5 * _fine(canvas, idx, "fine", 1)
    hyper = smoothstep(0.2, 0.8, mottle)
    _scar_colour(canvas, idx, prof * (1.0 - hyper), p)
    canvas.dm[idx] += prof * hyper * np.float32(0.35 * canvas.pigment_scale)
    canvas.dh[idx] += prof * np.float32(0.15) * (0.5 + 0.5 * _fine(canvas, idx, "fine", 2))


def _pitted(canvas, surface, frame, p, rng):
    spread = 0.5 * p["length_mm"] * MM
    n = p["count"]
    offsets = rng.normal(size=(n, 2)) * 0.45 * spread
    radii = rng.uniform(0.6, 1.6, n) * MM
    idx, uv = surface.decal(frame, spread * 2.0, facing=0.2)
    prof = np.zeros(len(idx), np.float32)
    for o, r in zip(offsets, radii):
        d = np.linalg.norm(uv - o, axis=1) / r
        prof = np.maximum(prof, (1.0 - smoothstep(0.7, 1.0, d)).astype(np.float32))
    _scar_colour(canvas, idx, prof * 0.8, p)


# ------------------------------------------------------------------------------------------------ tattoos
def sample_tattoos(rng, spec, index):
    place = _site(rng, spec["sites"])
    band = place["site"] in ("finger_band", "wrist_band")
    motif = draw(rng, sorted(BAND_MOTIFS) if band else sorted(MOTIFS))
    ink = draw(rng, spec["inks"])
    size = spec.get("site_size_mm", {}).get(place["site"], spec["size_mm"])   # a finger is smaller than a forearm
    p = {"motif": motif, "place": place, "size_mm": draw(rng, size), "angle": draw(rng, [-0.5, 0.5]),
         "ink": ink, "ink_srgb": spec["ink_colors"][ink], "age": draw(rng, spec["age"]),
         "outline": bool(rng.random() < spec["outline_probability"]) and ink != "black"}
    if place["site"] == "finger_band":
        place["finger"] = draw(rng, ["index", "middle", "ring", "pinky"])
    return p


TATTOO_STROKE = 0.3 * MM  # every stroke and shape grows by this much: lines of a few tenths of a mm would not read


def apply_tattoos(canvas: Canvas, surface: Surface, p: dict, rng) -> None:
    """Ink in the skin (multiplied into the albedo): a vector motif on a planar decal, or a band around a finger
    or the wrist; ink spreads and fades with age."""
    place, size = p["place"], p["size_mm"] * MM
    half = 0.5 * size
    if place["site"] in ("finger_band", "wrist_band"):
        idx, q = _band_coordinates(canvas, surface, place, half)
        sdf = BAND_MOTIFS[p["motif"]](q) * half
    else:
        frame = _frame(surface, _fitted(surface, place, half))
        idx, uv = surface.decal(frame, 1.5 * half, facing=0.35)
        q = rotate(uv, -p["angle"]) / half
        sdf = MOTIFS[p["motif"]](q) * half - TATTOO_STROKE
    blur = max(surface.texel_size, (0.08 + 0.25 * p["age"]) * MM)
    cover = (1.0 - smoothstep(-blur, blur, sdf)).astype(np.float32)
    fade = 1.0 - p["age"] * (0.35 + 0.25 * _fine(canvas, idx, "mid", 0))
    ink = _lin(p["ink_srgb"])
    aged = ink * (1 - 0.5 * p["age"]) + _lin([0.16, 0.26, 0.30]) * (0.5 * p["age"])
    density = (0.92 * fade * cover).astype(np.float32)
    if p["outline"]:
        line = (1.0 - smoothstep(0.05 * half - blur, 0.05 * half + blur, np.abs(sdf))).astype(np.float32)
        canvas.paint(idx, aged, 0.75 * density, mode="multiply")
        canvas.paint(idx, _lin([0.1, 0.1, 0.12]), 0.92 * fade * line, mode="multiply")
    else:
        canvas.paint(idx, aged, density, mode="multiply")


def _fitted(surface: Surface, place: dict, half: float) -> dict:
    """The placement with `along` moved just enough for a decal of half-size `half` (m) to stay on its site: on
    the back of the hand between the wrist and the knuckles, on the forearm between the wrist and its end."""
    site = place["site"]
    if site in ("dorsum", "palm"):
        knuckles = 0.5 * (surface.joint("index", 0) + surface.joint("pinky", 0))
        span = float(np.linalg.norm(knuckles - surface.joints[0]))
        lo, hi = 0.6 * half / span, 1.0 - 0.8 * half / span
    elif site in ("wrist_dorsal", "wrist_inner"):
        span = max(surface._forearm_extent() - 0.012, 1e-3)     # the site's `along` runs over this length
        lo, hi = (half + 0.002) / span, (span - half) / span
    else:
        return place
    along = float(np.clip(place["along"], lo, hi)) if lo <= hi else 0.5 * (lo + hi)
    return {**place, "along": along}


def _band_coordinates(canvas, surface, place, half):
    """Texels around a finger (its proximal segment) or the wrist and their motif coordinates (axial, around) /
    half size."""
    if place["site"] == "finger_band":
        idx, a, ang, r = _finger_band(canvas, surface, place["finger"], 0, 2.2 * half, along=0.45)
    else:
        wrist = surface.joints[0]
        extent = float(surface.vertices[:, 0].max() - wrist[0])
        centre = wrist + FOREARM_AXIS * (0.01 + place["along"] * max(extent - 0.02, 0.0))
        idx = _wrap_region(canvas, surface, centre[0] - 1.2 * half, centre[0] + 1.2 * half)
        pos = canvas.bake.position[idx].astype(np.float64)
        a = pos[:, 0] - centre[0]
        rel = pos[:, 1:] - pos[:, 1:].mean(0)
        r = np.linalg.norm(rel, axis=1)
        ang = np.arctan2(rel[:, 1], rel[:, 0])
    # Around the band in motif units, a whole number of motif periods per turn (seamless where angles wrap).
    radius = float(np.median(r)) if len(r) else 0.01
    around = _turns(ang, radius, BAND_PERIOD * half) * BAND_PERIOD
    return idx, np.stack([a / half, around], 1)


# -------------------------------------------------------------------------------------------------- moles
def sample_moles(rng, spec, index):
    return {"count": int(draw(rng, spec["count_range"], integer=True)), "diameter_mm": spec["diameter_mm"],
            "darkness": draw(rng, spec["darkness"]), "sites": spec["sites"], "seed_points": int(rng.integers(2 ** 31))}


def apply_moles(canvas: Canvas, surface: Surface, p: dict, rng) -> None:
    """Melanocytic naevi: round, well-defined brown to dark-brown spots of 1-5 mm, slightly irregular."""
    pr = np.random.default_rng(p["seed_points"])
    pts, _ = surface.sample_points(pr, p["count"], p["sites"])
    lo, hi = p["diameter_mm"]
    radius = 0.5 * MM * np.exp(pr.uniform(np.log(lo), np.log(hi), len(pts)))
    dark = p["darkness"] * pr.uniform(0.6, 1.2, len(pts)) * (1.2 + 0.6 * canvas.pigment_scale)
    spots(canvas, surface, pts, radius, dark, softness=0.35, irregular=0.25, blood=0.12 * np.ones(len(pts)))


# -------------------------------------------------------------------------------------------- nail colours
NAIL_PATTERNS = ("full", "french", "chipped", "glitter", "ombre", "accent")


def sample_nail_colors(rng, spec, index):
    polish = spec["polishes"][index % len(spec["polishes"])]
    p = {"polish": polish["name"], "srgb": polish["srgb"], "finish": polish["finish"],
         "pattern": polish.get("pattern", "full"), "coats": draw(rng, [0.85, 1.0])}
    if p["pattern"] in ("ombre", "accent"):
        other = spec["polishes"][(index + 7) % len(spec["polishes"])]
        p["second_srgb"] = other["srgb"]
    return p


FINISH_ROUGHNESS = {"gloss": 0.08, "metallic": 0.18, "glitter": 0.15, "matte": 0.5}


def apply_nail_colors(canvas: Canvas, surface: Surface, p: dict, rng) -> None:
    """Polish on the nail plates only (inset from the fold and sides), glossy in the roughness map."""
    b = canvas.bake
    idx = np.nonzero(b.label == FACE_LABEL_IDS["nail"])[0]
    if not len(idx):
        return
    u, v = b.fields["nail_u"][idx].astype(np.float32), b.fields["nail_v"][idx].astype(np.float32)
    finger = b.fields["finger"][idx]
    inset = smoothstep(0.07, 0.11, u - 0.3 * v ** 4) * (1.0 - smoothstep(0.88, 0.95, np.abs(v)))
    alpha = smoothstep(0.5, 1.0, b.fields["nail"][idx].astype(np.float32)) * inset * np.float32(p["coats"])
    base = _lin(p["srgb"])
    rgb = np.repeat(base[None], len(idx), 0) * (1.0 + 0.03 * _fine(canvas, idx))[:, None]
    pattern = p["pattern"]
    if pattern == "french":
        tip = smoothstep(0.74, 0.78, u - 0.1 * v * v)
        rgb = rgb * (1 - tip)[:, None] + np.array([0.86, 0.85, 0.83], np.float32) * tip[:, None]
        alpha = alpha * (0.55 + 0.45 * tip)
    elif pattern == "ombre":
        t = smoothstep(0.15, 0.95, u)[:, None]
        rgb = rgb * (1 - t) + _lin(p["second_srgb"]) * t
    elif pattern == "accent":
        ring = finger == FINGERS.index("ring")
        rgb[ring] = _lin(p["second_srgb"])
    elif pattern == "chipped":
        chips = smoothstep(0.9, 1.3, _fine(canvas, idx, "fine", 2) + 2.2 * smoothstep(0.7, 1.0, u))
        alpha = alpha * (1.0 - chips)
    if p["finish"] == "glitter":
        sparkle = smoothstep(1.6, 2.2, _fine(canvas, idx, "pore", 0)).astype(np.float32)
        rgb = rgb * (1 - sparkle)[:, None] + np.array([0.9, 0.88, 0.8], np.float32) * sparkle[:, None]
    canvas.paint(idx, rgb, alpha, roughness=FINISH_ROUGHNESS[p["finish"]])


OVERLAYS = {
    "bandage": (sample_bandage, apply_bandage),
    "palm_prints": (sample_palm_prints, apply_palm_prints),
    "scars": (sample_scars, apply_scars),
    "tattoos": (sample_tattoos, apply_tattoos),
    "moles": (sample_moles, apply_moles),
    "nail_colors": (sample_nail_colors, apply_nail_colors),
}
