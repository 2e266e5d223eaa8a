"""Environment maps for datasets: per frame, a map of a set (the built-in CC0 maps, a folder, or one file) turned to a
random azimuth, at a strength that brings the map's mean radiance to a common level with some spread, and with a
white balance drawn around daylight, as the `environment` field of the frame's lights document
(schemas/lights.schema.json; render/environment.py draws it).

Exposure keeps skin from washing out: the strength is then capped so that a white card turned to the frame's
brightest side (render/environment.key_white, the incident light, not the hand's own brightness) renders at most
KEY_WHITE. A map with a sun in front of the hand is exposed for the sun, as a camera metering the scene's light
would; a dark hand stays dark and a light one light, and neither clips where it is lit diffusely (the specular
highlights still may).

Planning checks every map of the set once (`EnvironmentSet`): one that does not decode, is not equirectangular or
holds NaN/Inf or negative values is left out and recorded (dataset.json's plan description), so one bad file among
hundreds never ends a long run; a set with no usable map is refused in one line. A map's mean radiance (luminance,
weighted by solid angle) is measured then, so strength is a function of the map and the frame's uniforms only.

A frame draws UNIFORMS uniforms from its own stream ([seed, ENVIRONMENT_STREAM, i] in plan.py): map, rotation,
strength, white balance, background blur.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from darthand.dataset.lighting import kelvin_to_rgb
from darthand.errors import InputError
from darthand.render import environment

UNIFORMS = 8
TARGET_RADIANCE = 0.6          # a map's solid-angle mean luminance is scaled to this (a white wall facing it: 0.6)
STRENGTH_STOPS = (-0.75, 0.75)  # then varied by this many stops
KELVIN_RANGE = (5000.0, 8000.0)  # white balance: the light's colour as a camera balanced for 6500 K sees it
BLUR_RANGE_DEG = (1.0, 3.0)    # the backdrop's blur (render/environment.background_view): out of focus
ROTATION, STRENGTH, KELVIN, BLUR = 1, 2, 3, 4
MATCH_LIMITS = (0.25, 2.0)     # a photo backdrop scales the light by its level / TARGET_RADIANCE within these
KEY_WHITE = 1.0                # the exposure cap: white (8-bit 255) for a white card facing the brightest light


def list_maps(folder) -> list[str]:
    """Sorted relative paths (posix) of the .exr/.hdr files under `folder`, recursively (by suffix, not opened)."""
    root = Path(folder)
    found = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames.sort()
        found += [Path(dirpath, name).relative_to(root).as_posix() for name in filenames
                  if name.lower().endswith(environment.SUFFIXES) and not name.startswith(".")]
    if not found:
        raise InputError(f"{folder}: no environment maps ({', '.join(environment.SUFFIXES)})")
    return sorted(found)


class EnvironmentSet:
    """The maps frames draw from: 'builtin' (render/environment.py's CC0 set), a folder of maps or one map file.
    maps: [(name or path as the lights document gives it, mean luminance)]; skipped: [{'file', 'reason'}]."""

    def __init__(self, environments="builtin"):
        self.spec = environments
        if environments in (None, "builtin"):
            self.kind, names = "builtin", environment.list_builtin()
        else:
            path = Path(str(environments))
            if path.is_dir():
                self.kind, names = "folder", [str(path.resolve() / n) for n in list_maps(path)]
            elif path.is_file():
                self.kind, names = "file", [str(path.resolve())]
            else:
                raise InputError(f"environments: {environments!r} is neither 'builtin', a folder of maps nor a map")
        self.maps: list[tuple[str, float]] = []
        self._lighting: dict = {}          # name -> render/environment.light_summary, made when first drawn
        self.skipped: list[dict] = []
        for name in names:
            try:
                self.maps.append((name, mean_luminance(environment.read_map(name))))
            except InputError as e:
                self.skipped.append({"file": name, "reason": str(e)})
        if not self.maps:
            raise InputError(f"environments: no usable map in {environments!r} ({self.skipped[0]['reason']})")

    def describe(self) -> dict:
        return {"kind": self.kind, "maps": len(self.maps), "skipped": self.skipped}

    def sample(self, u: np.ndarray) -> tuple[dict, dict]:
        """(the lights document's 'environment' field, the frame's sampling record) from UNIFORMS uniforms u."""
        name, level = self.maps[min(int(u[0] * len(self.maps)), len(self.maps) - 1)]
        stops = STRENGTH_STOPS[0] + (STRENGTH_STOPS[1] - STRENGTH_STOPS[0]) * float(u[STRENGTH])
        kelvin = KELVIN_RANGE[0] + (KELVIN_RANGE[1] - KELVIN_RANGE[0]) * float(u[KELVIN])
        doc = {"map": name, "rotation": round(360.0 * float(u[ROTATION]), 3),
               "strength": round(TARGET_RADIANCE / max(level, 1e-6) * 2.0 ** stops, 6),
               "white_balance": white_balance(kelvin), "frame": "camera"}
        capped = exposure_capped(doc, self.key_lighting(name))
        record = {"rig": "environment", "map": Path(name).stem, "kelvin": round(kelvin, 1),
                  "stops": round(stops, 4),
                  "capped_stops": round(float(np.log2(capped["strength"] / doc["strength"])), 4)}
        return capped, record

    def key_lighting(self, name: str):
        """A map's light_summary for the exposure's cap, made once per map of the set (render/environment.py keeps
        only MAPS_KEPT maps' whole lighting: a set of hundreds would prepare a map again for every frame)."""
        if name not in self._lighting:
            self._lighting[name] = environment.light_summary(environment.map_lighting(name))
        return self._lighting[name]

    @staticmethod
    def backdrop(u: np.ndarray) -> dict:
        """The background spec that shows the frame's environment behind the hand, blurred by a drawn angle."""
        blur = BLUR_RANGE_DEG[0] + (BLUR_RANGE_DEG[1] - BLUR_RANGE_DEG[0]) * float(u[BLUR])
        return {"environment": True, "blur": round(blur, 3)}


def match_background(doc: dict, pixels: np.ndarray) -> dict:
    """The environment field `doc` matched to a photograph behind the hand: its strength scaled so that the light
    has the photo's mean level (within MATCH_LIMITS), its white balance tinted by the photo's mean colour (half of
    it, in a product with the drawn tint). pixels (H, W, 3) linear. A photo's own light is unknown, so its level
    and colour are what a viewer judges the hand against."""
    mean = np.asarray(pixels, np.float32).reshape(-1, 3).mean(0).astype(np.float64)
    level = float(mean @ environment.LUMA)
    scale = float(np.clip(level / TARGET_RADIANCE, *MATCH_LIMITS))
    tint = np.sqrt(np.maximum(mean, 1e-4) / max(float(mean.mean()), 1e-4))
    balance = np.asarray(doc.get("white_balance", [1.0, 1.0, 1.0])) * tint
    return exposure_capped({**doc, "strength": round(float(doc.get("strength", 1.0)) * scale, 6),
                            "white_balance": [round(float(c), 5) for c in balance / balance.mean()]})


def exposure_capped(doc: dict, lighting=None) -> dict:
    """The environment field `doc` with its strength lowered, where needed, so that a white Lambertian card facing
    the camera's side renders at most KEY_WHITE under it (render/environment.key_white; lighting: its map's, as
    key_white takes it). A frame-'world' field (a user's jobs file) is left as it is: where its light comes from
    depends on a camera not known here."""
    if doc.get("frame", "camera") != "camera":
        return doc
    unit = environment.Environment(str(doc["map"]), float(doc.get("rotation", 0.0)), 1.0,
                                   tuple(float(c) for c in doc.get("white_balance", (1.0, 1.0, 1.0))))
    cap = KEY_WHITE / max(environment.key_white(unit, lighting), 1e-9)
    strength = float(doc.get("strength", 1.0))
    return doc if strength <= cap else {**doc, "strength": round(cap, 6)}


def mean_luminance(pixels: np.ndarray) -> float:
    """Solid-angle mean of an equirectangular map's luminance (Rec. 709 weights). pixels (H, 2H, 3) linear."""
    weight = environment.texel_solid_angles(pixels.shape[0])[:, 0]
    luminance = pixels[..., :3] @ environment.LUMA.astype(np.float32)
    return float((luminance.mean(1) * weight).sum() / weight.sum())


def white_balance(kelvin: float) -> list[float]:
    """Per-channel multipliers (mean 1) that tint neutral light as a source at `kelvin` looks to a camera
    balanced for 6500 K."""
    ratio = np.asarray(kelvin_to_rgb(kelvin)) / np.asarray(kelvin_to_rgb(6500.0))
    return [round(float(c), 5) for c in ratio / ratio.mean()]
