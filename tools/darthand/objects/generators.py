"""The procedural objects: one function per kind, from an item's resolved parameters (metres, colours linear RGB)
to a closed mesh with its faces assigned to PBR parts. Shapes are built in the object's frame (+z its axis, or a
card's or phone's thin axis); the build centres them on their bounding box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darthand.objects import shapes as S
from darthand.objects.creases import face_normals


@dataclass
class Shape:
    """A generated object: vertices (N, 3) float64 metres, faces (F, 3) int64 outward, face_part (F,) index into
    parts (dicts: name, base_color linear RGB, roughness, metallic)."""

    vertices: np.ndarray
    faces: np.ndarray
    face_part: np.ndarray
    parts: list[dict]


def part(name: str, color, roughness: float, metallic: float = 0.0) -> dict:
    """A catalogue part: name, base_color (linear RGB), roughness, metallic."""
    return {"name": name, "base_color": [round(float(c), 4) for c in color], "roughness": round(float(roughness), 4),
            "metallic": round(float(metallic), 4)}


def one_part(mesh, p: dict) -> Shape:
    """The mesh as a single part `p`."""
    v, f = mesh
    return Shape(v, f, np.zeros(len(f), np.int16), [p])


def centroids(mesh) -> np.ndarray:
    """Face centroids (F, 3)."""
    v, f = mesh
    return v[f].mean(axis=1)


# ---------------------------------------------------------------- drinkware
def mug(p: dict) -> Shape:
    """A mug: a surface of revolution with a cavity (wall `wall`, floor `floor`) and a C-shaped handle tube whose
    ends sink into the wall, joined into one closed mesh."""
    R, H, wall, floor, r = p["diameter"] / 2, p["height"], p["wall"], p["floor"], p["handle_radius"]
    fillet = min(0.003, wall * 0.8)
    body = S.revolve([(0, 0), (R - fillet, 0), (R, fillet), (R, H), (R - wall, H), (R - wall, floor + fillet),
                      (R - wall - fillet, floor), (0, floor)], 64)
    inset = max(wall - 0.6 * r, 0.0) * 0.5                  # the handle's end caps stay inside the wall
    t = np.linspace(-np.pi / 2, np.pi / 2, 24)
    path = np.column_stack([R - inset + p["handle_reach"] * np.cos(t), np.zeros_like(t),
                            H * p["handle_height"] + p["handle_span"] / 2 * np.sin(t)])
    mesh = S.boolean([body, S.tube(path, r, 14)])
    return one_part(mesh, part("ceramic", p["color"], p["roughness"]))


def cup(p: dict) -> Shape:
    """A handle-less cup or tumbler: a tapered surface of revolution with a cavity."""
    Rb, Rt, H, wall = p["bottom_diameter"] / 2, p["top_diameter"] / 2, p["height"], p["wall"]
    floor = p["floor"]
    rim = Rt - wall * 0.5
    mesh = S.revolve([(0, 0), (Rb, 0), (Rt, H), (rim - wall * 0.5, H),
                      (Rb - wall + (Rt - Rb) * floor / H, floor), (0, floor)], 64)
    return one_part(mesh, part("cup", p["color"], p["roughness"]))


def bottle(p: dict) -> Shape:
    """A bottle: body, rounded shoulder, neck and cap as one surface of revolution; parts body, label, cap."""
    R, H, rn, cap_h = p["diameter"] / 2, p["height"], p["neck_diameter"] / 2, p["cap_height"]
    shoulder_h, neck_h = p["shoulder_height"], p["neck_height"]
    z_sh = H - cap_h - neck_h - shoulder_h
    s = np.linspace(0, 1, 9)[1:-1]
    shoulder = [(rn + (R - rn) * np.cos(np.pi / 2 * u), z_sh + shoulder_h * np.sin(np.pi / 2 * u)) for u in s]
    label0, label1 = z_sh * p["label_from"], z_sh * p["label_to"]
    cap_r = rn * 1.12
    profile = [(0, 0.002), (R - 0.005, 0), (R, 0.005), (R, label0), (R, label1), (R, z_sh), *shoulder,
               (rn, z_sh + shoulder_h), (rn, H - cap_h), (cap_r, H - cap_h), (cap_r, H - 0.001),
               (cap_r - 0.001, H), (0, H)]
    mesh = S.revolve(profile, 48)
    c = centroids(mesh)
    radius = np.hypot(c[:, 0], c[:, 1])
    face_part = np.zeros(len(mesh[1]), np.int16)
    face_part[(c[:, 2] > label0) & (c[:, 2] < label1) & (radius > 0.97 * R)] = 1
    face_part[c[:, 2] > H - cap_h] = 2
    parts = [part("plastic", p["color"], 0.15), part("label", p["label_color"], 0.5),
             part("cap", p["cap_color"], 0.4)]
    return Shape(*mesh, face_part, parts)


def can(p: dict) -> Shape:
    """A drinks can: a printed body between necked-in metal lids (one surface of revolution)."""
    R, H = p["diameter"] / 2, p["height"]
    neck = min(0.006, R * 0.2)
    profile = [(0, 0.004), (R - neck - 0.002, 0.001), (R - neck, 0), (R - 0.002, 0.003), (R, 0.009), (R, H - 0.012),
               (R - neck, H - 0.002), (R - neck, H), (R - neck - 0.001, H), (R - neck - 0.0015, H - 0.003),
               (0, H - 0.003)]
    mesh = S.revolve(profile, 56)
    c = centroids(mesh)
    face_part = np.where((c[:, 2] > 0.009) & (c[:, 2] < H - 0.012), 0, 1).astype(np.int16)
    parts = [part("print", p["color"], 0.3, 0.6), part("lid", (0.75, 0.75, 0.77), 0.25, 1.0)]
    return Shape(*mesh, face_part, parts)


# ---------------------------------------------------------------- pens
def pen(p: dict) -> Shape:
    """A round pen: a conical writing tip, a body, a cap end; parts tip, body, end."""
    r, L = p["diameter"] / 2, p["length"]
    tip = 0.013
    profile = [(0, 0), (0.0004, 0.0003), (0.0009, 0.002), (r * 0.7, tip), (r, tip + 0.002), (r, L - 0.03),
               (r, L - 0.004), (r * 0.75, L), (0, L)]
    mesh = S.revolve(profile, 24)
    c = centroids(mesh)
    face_part = np.select([c[:, 2] < tip, c[:, 2] > L - 0.03], [0, 2], 1).astype(np.int16)
    parts = [part("tip", (0.6, 0.6, 0.62), 0.3, 1.0), part("body", p["color"], p["roughness"]),
             part("end", p["end_color"], 0.4)]
    return Shape(*mesh, face_part, parts)


def pencil(p: dict) -> Shape:
    """A hexagonal pencil: graphite point, sharpened wood, painted body, metal ferrule, eraser."""
    r, L = p["diameter"] / 2, p["length"]
    cone, ferrule, eraser = 0.018, 0.012, 0.007
    profile = [(0, 0), (0.0007, 0.0015), (r, cone), (r, L - ferrule - eraser), (r * 0.98, L - eraser),
               (r * 0.92, L - eraser), (r * 0.9, L - 0.001), (r * 0.8, L), (0, L)]
    mesh = S.revolve(profile, 6, phase=np.pi / 6)
    c = centroids(mesh)
    z = c[:, 2]
    face_part = np.select([z < 0.0015, z < cone, z < L - ferrule - eraser, z < L - eraser], [0, 1, 2, 3],
                          4).astype(np.int16)
    parts = [part("graphite", (0.05, 0.05, 0.05), 0.4, 0.3), part("wood", (0.62, 0.42, 0.24), 0.8),
             part("paint", p["color"], 0.45), part("ferrule", (0.7, 0.68, 0.6), 0.3, 1.0),
             part("eraser", (0.8, 0.35, 0.35), 0.9)]
    return Shape(*mesh, face_part, parts)


# ---------------------------------------------------------------- flat things
def phone(p: dict) -> Shape:
    """A phone: a rounded slab (thin along z) with its flat top as the screen."""
    mesh = S.rounded_slab((p["width"], p["length"], p["thickness"]), p["corner_radius"], p["edge_radius"], 10, 4)
    unit, _ = face_normals(*mesh)
    face_part = (unit[:, 2] > 0.9999).astype(np.int16) * (centroids(mesh)[:, 2] > 0)
    parts = [part("case", p["color"], p["roughness"], p["metallic"]), part("screen", (0.01, 0.01, 0.012), 0.05)]
    return Shape(*mesh, face_part.astype(np.int16), parts)


def card(p: dict) -> Shape:
    """A card (credit, playing, business): a thin slab with rounded corners and square rims (thin along z)."""
    mesh = S.rounded_slab((p["width"], p["length"], p["thickness"]), p["corner_radius"], 0.0, 8)
    return one_part(mesh, part("card", p["color"], p["roughness"], p.get("metallic", 0.0)))


def box(p: dict) -> Shape:
    """A box (carton, matchbox, gift box): a slab with slightly rounded edges."""
    mesh = S.rounded_slab((p["width"], p["depth"], p["height"]), p["edge_radius"], p["edge_radius"], 3, 3)
    return one_part(mesh, part("board", p["color"], p["roughness"]))


# ---------------------------------------------------------------- balls and fruit
def ball(p: dict) -> Shape:
    """A ball: a sphere of `diameter` (slightly flattened by `flatten` for fruit such as an orange)."""
    R = p["diameter"] / 2
    mesh = S.ellipsoid((R, R, R * (1 - p.get("flatten", 0.0))), 3)
    return one_part(mesh, part("skin", p["color"], p["roughness"]))


def apple(p: dict) -> Shape:
    """An apple: a flattened sphere of revolution with a dimple at the stalk and one at the base."""
    R, d = p["diameter"] / 2, p["dimple"]
    theta = np.linspace(0, np.pi, 33)
    r = R * np.sin(theta) * (1 + 0.06 * np.sin(theta) * (np.pi - theta) / np.pi)
    z = -R * p["squash"] * np.cos(theta) + d * np.exp(-(theta / 0.45) ** 2) - d * np.exp(-((np.pi - theta) / 0.45) ** 2)
    r[0] = r[-1] = 0.0
    mesh = S.revolve(np.column_stack([r, z]), 48)
    return one_part(mesh, part("skin", p["color"], p["roughness"]))


# ---------------------------------------------------------------- tools
def screwdriver(p: dict) -> Shape:
    """A screwdriver: a metal shaft with a flattened tip and a bulging handle, one surface of revolution (tip at the
    bottom, +z toward the handle); parts shaft, handle."""
    rs, shaft, rh, handle = p["shaft_diameter"] / 2, p["shaft_length"], p["handle_diameter"] / 2, p["handle_length"]
    profile = [(0, 0), (rs * 0.9, 0.0005), (rs, 0.006), (rs, shaft), (rs * 2.2, shaft + 0.002),
               (rh * 0.8, shaft + 0.012), (rh, shaft + 0.03), (rh * 0.95, shaft + handle - 0.012),
               (rh * 0.75, shaft + handle - 0.002), (rh * 0.5, shaft + handle), (0, shaft + handle)]
    mesh = S.revolve(profile, 24)
    face_part = (centroids(mesh)[:, 2] > shaft + 0.001).astype(np.int16)
    parts = [part("shaft", (0.72, 0.72, 0.74), 0.25, 1.0), part("handle", p["color"], 0.35)]
    return Shape(*mesh, face_part, parts)


def hammer(p: dict) -> Shape:
    """A hammer: an oval handle along z and a head across it at the top; parts handle, head."""
    L, hw, hd = p["length"], p["handle_width"], p["handle_depth"]
    head_len, head_w = p["head_length"], p["head_width"]
    handle = S.rounded_slab((hw, hd, L), hd / 2, hd / 2 * 0.9, 6, 4)
    head_z = L / 2 - head_w / 2
    head = S.transformed(S.rounded_slab((head_len, head_w, head_w), head_w * 0.2, head_w * 0.15, 4, 3),
                         offset=(head_len * 0.12, 0, head_z))
    mesh = S.boolean([handle, head])
    c = centroids(mesh)
    in_head = c[:, 2] > head_z - head_w / 2 - 1e-4
    parts = [part("handle", p["color"], 0.6), part("head", (0.55, 0.55, 0.58), 0.35, 1.0)]
    return Shape(*mesh, in_head.astype(np.int16), parts)


def wrench(p: dict) -> Shape:
    """An open-ended spanner: a flat bar along z (thin along y) with a disc at each end, the top one cut open by
    its jaw (width `jaw`)."""
    L, w, t, D = p["length"], p["width"], p["thickness"], p["head_diameter"]
    bar = S.rounded_slab((w, t, L - D), w * 0.3, t * 0.3, 4, 2)
    disc = S.transformed(S.rounded_slab((D, D, t * 1.1), D / 2, t * 0.3, 10, 2), S.rotation_x(np.pi / 2))
    top = S.transformed(disc, offset=(0, 0, (L - D) / 2))
    bottom = S.transformed(S.transformed(disc, np.diag([0.8, 1.0, 0.8])), offset=(0, 0, -(L - D) / 2))
    solid = S.boolean([bar, top, bottom])
    jaw = S.rounded_slab((p["jaw"], t * 3, D * 0.8), 0.0005, 0.0, 2)
    mesh = S.boolean([solid, S.transformed(jaw, offset=(0, 0, (L - D) / 2 + D * 0.3))], op="difference")
    return one_part(mesh, part("steel", (0.7, 0.7, 0.72), 0.3, 1.0))


def pliers(p: dict) -> Shape:
    """Pliers lying in the xz plane (thin along y): a tapered nose above the pivot, two handles spreading below it
    with coated grips; parts metal, grips."""
    L, nose, t = p["length"], p["nose_length"], p["thickness"]
    pivot = L / 2 - nose
    points = []
    for z, half in ((L / 2, 0.002), (pivot, 0.009), (pivot - 0.012, 0.008)):
        for x in (-half, half):
            for y in (-t / 2, t / 2):
                points.append((x, y, z))
    head = S.convex_hull(np.array(points))
    s = np.linspace(0, 1, 14)
    handles = []
    for side in (-1, 1):
        path = np.column_stack([side * (0.004 + p["spread"] * s ** 1.3), np.zeros_like(s),
                                pivot - 0.006 - s * (L - nose - 0.006 - p["grip_radius"])])
        handles.append(S.tube(path, p["grip_radius"], 12))
    mesh = S.boolean([head, *handles])
    grips = centroids(mesh)[:, 2] < pivot - 0.02
    parts = [part("metal", (0.6, 0.6, 0.63), 0.3, 1.0), part("grips", p["color"], 0.7)]
    return Shape(*mesh, grips.astype(np.int16), parts)


KINDS = {"mug": mug, "cup": cup, "bottle": bottle, "can": can, "pen": pen, "pencil": pencil, "phone": phone,
         "card": card, "box": box, "ball": ball, "apple": apple, "screwdriver": screwdriver, "hammer": hammer,
         "wrench": wrench, "pliers": pliers}
