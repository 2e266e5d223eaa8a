"""One accessory of the catalogue: fitted (rigid items) and generated on a hand, as the stage's working record."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from darthand.accessories import catalog as cat
from darthand.accessories.attach import apply
from darthand.accessories.fit import Fit, fit_ring, fit_wrist, wrist_axis
from darthand.accessories.generators import rigid_generator
from darthand.accessories.generators.glove import glove
from darthand.accessories.mesh import AccessoryMesh
from darthand.model.hand_model import HandModel


@dataclass
class Built:
    """One generated accessory: its expanded entry, local-frame mesh, fit (None for gloves) and clearance."""

    entry: dict
    mesh: AccessoryMesh
    fit: Fit | None
    clearance: float
    figures: dict = field(default_factory=dict)

    @property
    def id(self) -> str:
        return self.entry["id"]

    @property
    def rest(self) -> np.ndarray:
        return np.eye(4) if self.fit is None else self.fit.rest

    @property
    def world_vertices(self) -> np.ndarray:
        return apply(self.rest, self.mesh.vertices)


def axial_width(entry: dict) -> float:
    """How much of the bone (m) a rigid accessory's bore spans, for the section slab."""
    if entry["type"] == "ring":
        return float(entry["width"])
    if entry["type"] == "watch":
        return float(entry["strap_width"])
    style = entry["style"]
    if style in ("bangle", "cuff"):
        return float(entry["width"])
    if style in ("chain", "charm"):
        return 2 * 4.3 * float(entry["wire"])
    if style == "beads":
        return float(entry["bead_diameter"])
    return 2.0 * float(entry["thickness"])


def generate(model: HandModel, entry: dict, seed: int, clearance: float | None = None) -> Built:
    """Fit (rigid items) and generate one catalogue entry (metres) on `model`."""
    rng = cat.item_rng(seed, entry["id"])
    what = f"accessory {entry['id']}"
    if entry["type"] == "glove":
        return Built(entry, glove(model, entry, rng), None, float(entry["clearance"]))
    clearance = float(entry["clearance"]) if clearance is None else clearance
    width = axial_width(entry)
    for _ in range(2):
        if entry["type"] == "ring":
            fit = fit_ring(model, entry["finger"], width, clearance, float(entry.get("t", 0.5)), what)
        else:
            fit = fit_wrist(model, _wrist_offset(model, entry, width), width, clearance, what)
        mesh = rigid_generator(entry["type"])({**entry, **fit.bore}, cat.item_rng(seed, entry["id"]))
        # Parts may reach past the nominal width (a rope's strands, a signet's shoulders): fit again over them.
        extent = 2 * float(np.abs(mesh.vertices[:, 0]).max())
        if entry["type"] == "watch" or extent <= width + 1e-4:      # a watch's case stands clear of the wrist
            break
        width = extent
    return Built(entry, mesh, fit, clearance)


def _wrist_offset(model: HandModel, entry: dict, width: float) -> float:
    """The entry's offset along the forearm, pulled back if the item would hang off the forearm's end."""
    j0, axis = wrist_axis(model)
    end = float(((model.v_template - j0) @ axis).max())
    return min(float(entry.get("offset", 0.03)), end - width / 2 - 0.002)
