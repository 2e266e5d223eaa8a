"""Random lights for datasets: ambient light plus a key light and sometimes a second (directional or point) light,
with random directions and intensities and colours from a palette of real light sources (the controls DART's GUI
exposes: ambient and directional lights, direction, intensity, colour).

Colours: each source of the palette is a black body at its correlated colour temperature, its chromaticity on the
Planckian locus by Kim et al.'s cubic fit (2002, valid 1667-25000 K), turned into linear sRGB (D65) and scaled so the
brightest channel is 1 (intensity carries the brightness). Documents are schemas/lights.schema.json.
"""

from __future__ import annotations

import math

import numpy as np

# Typical correlated colour temperatures (kelvin) of real sources.
PALETTE_K = {
    "candle": 1850, "tungsten_40w": 2600, "tungsten_100w": 2850, "warm_led": 3000, "halogen": 3200,
    "neutral_led": 4000, "cool_fluorescent": 4200, "noon_sun": 5500, "flash": 5600, "overcast": 6500,
    "shade": 7500, "blue_sky": 10000,
}
AMBIENT_RANGE = (0.08, 0.3)
KEY_RANGE = (0.5, 1.2)
FILL_RANGE = (0.1, 0.5)
SECOND_LIGHT_SHARE = 0.6
POINT_SHARE = 0.5
POINT_DISTANCE = (0.25, 0.8)          # metres from the hand's centre
KEY_MAX_Z = 0.25                      # the key light comes mostly from the camera's side (toward-light z <= this)
UNIFORMS = 16                         # uniforms a rig consumes, whatever it draws


def planckian_xy(kelvin: float) -> tuple[float, float]:
    """CIE 1931 (x, y) of a black body at `kelvin` (Kim et al. 2002 cubic spline, 1667-25000 K)."""
    T = float(kelvin)
    if not 1667 <= T <= 25000:
        raise ValueError(f"colour temperature {T} K is outside 1667..25000")
    if T <= 4000:
        x = -0.2661239e9 / T**3 - 0.2343589e6 / T**2 + 0.8776956e3 / T + 0.179910
    else:
        x = -3.0258469e9 / T**3 + 2.1070379e6 / T**2 + 0.2226347e3 / T + 0.240390
    if T <= 2222:
        y = -1.1063814 * x**3 - 1.34811020 * x**2 + 2.18555832 * x - 0.20219683
    elif T <= 4000:
        y = -0.9549476 * x**3 - 1.37418593 * x**2 + 2.09137015 * x - 0.16748867
    else:
        y = 3.0817580 * x**3 - 5.87338670 * x**2 + 3.75112997 * x - 0.37001483
    return x, y


_XYZ_TO_SRGB = np.array([[3.2404542, -1.5371385, -0.4985314],
                         [-0.9692660, 1.8760108, 0.0415560],
                         [0.0556434, -0.2040259, 1.0572252]])


def kelvin_to_rgb(kelvin: float) -> list[float]:
    """Linear sRGB of a black body at `kelvin`, brightest channel 1 (negative components clipped)."""
    x, y = planckian_xy(kelvin)
    rgb = np.clip(_XYZ_TO_SRGB @ np.array([x / y, 1.0, (1 - x - y) / y]), 0, None)
    return [round(float(c), 5) for c in rgb / rgb.max()]


PALETTE = {name: kelvin_to_rgb(k) for name, k in PALETTE_K.items()}
_NAMES = tuple(PALETTE)


def random_rig(u: np.ndarray, hand_centre=(0.0, 0.0, 0.0)) -> tuple[dict, dict]:
    """(lights document, record) from UNIFORMS uniforms u in [0, 1): ambient; a directional key light with shadows,
    in the camera's frame, from a direction uniform on the part of the sphere toward the camera (z <= KEY_MAX_Z);
    with probability SECOND_LIGHT_SHARE a second light without shadows: directional from anywhere (camera frame), or
    a point light (world frame) at POINT_DISTANCE from `hand_centre` with its intensity scaled by the squared
    distance, so that it lights the hand like a directional light of the same nominal intensity."""
    names = [_NAMES[min(int(x * len(_NAMES)), len(_NAMES) - 1)] for x in u[:3]]
    doc: dict = {"ambient": {"color": PALETTE[names[0]], "intensity": _lerp(AMBIENT_RANGE, u[3])}, "lights": []}
    toward = _sphere(u[4], u[5], -1.0, KEY_MAX_Z)
    doc["lights"].append({"type": "directional", "direction": [-c for c in toward], "color": PALETTE[names[1]],
                          "intensity": _lerp(KEY_RANGE, u[6]), "shadows": True, "frame": "camera"})
    record = {"ambient": names[0], "key": names[1], "second": None}
    if u[7] < SECOND_LIGHT_SHARE:
        direction = _sphere(u[8], u[9])
        intensity = _lerp(FILL_RANGE, u[10])
        if u[11] < POINT_SHARE:
            r = POINT_DISTANCE[0] + (POINT_DISTANCE[1] - POINT_DISTANCE[0]) * float(u[12])
            light = {"type": "point", "position": [round(float(c) + r * d, 5) for c, d in zip(hand_centre, direction)],
                     "intensity": round(intensity * r * r, 5), "frame": "world"}
        else:
            light = {"type": "directional", "direction": direction, "intensity": intensity, "frame": "camera"}
        doc["lights"].append({**light, "color": PALETTE[names[2]], "shadows": False})
        record["second"] = f"{light['type']}:{names[2]}"
    return doc, record


def _sphere(u: float, v: float, z_lo: float = -1.0, z_hi: float = 1.0) -> list[float]:
    """A unit vector uniform on the zone z_lo <= z <= z_hi of the sphere (Archimedes: z uniform)."""
    z = z_lo + (z_hi - z_lo) * float(u)
    r, phi = math.sqrt(max(0.0, 1 - z * z)), 2 * math.pi * float(v)
    return [round(r * math.cos(phi), 6), round(r * math.sin(phi), 6), round(z, 6)]


def _lerp(pair, u) -> float:
    return round(float(pair[0] + (pair[1] - pair[0]) * float(u)), 4)
