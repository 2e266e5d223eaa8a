"""The texture catalogue: the spec a person edits (assets_src/textures/catalog.json) and its expansion into
entries, each with every parameter needed to render it.

Ids are stable: `<tone>_<category>_<NN>` for overlays (one run of each overlay category per tone) and
`base_<category>_<NN>` for base variations. Every random draw comes from a generator seeded from (catalogue
seed, id), so an entry never depends on which others exist, their order, or how many are built.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import read_json
from darthand.schemas import check_schema
from darthand.textures import color
from darthand.textures.overlays import OVERLAYS
from darthand.textures.skin import BASE_VARIATIONS, sample_base

SPEC_FORMAT = "darthand-texture-spec"
OVERLAY_CATEGORIES = tuple(OVERLAYS)
BASE_CATEGORIES = tuple(BASE_VARIATIONS)


def default_spec_path() -> Path:
    return Path(__file__).resolve().parents[3] / "assets_src" / "textures" / "catalog.json"


@dataclass(frozen=True)
class Entry:
    """One catalogue variant.

    id        stable name, e.g. 'light_tattoos_07' or 'base_freckles_03'
    category  overlay category (OVERLAY_CATEGORIES) or base variation (BASE_CATEGORIES)
    kind      'overlay' or 'base_variation'
    tone      'dark', 'brown' or 'light' (for base variations: the nearest named tone)
    mst       position on the 10-step skin-tone scale (1 lightest .. 10 darkest)
    tone_srgb the tone scale's colour at `mst` (3 floats, sRGB): the base colour, so an entry renders alone
    offset    global skin-tone offset added to the sRGB albedo, within the spec's range, and never lifting the
              tone's brightest channel above MAX_TONE_SRGB (see there)
    seed      63-bit seed derived from (catalogue seed, id)
    index     number within its (tone, category) run
    params    {'skin': base-skin parameters, category: category parameters}, JSON-able
    """

    id: str
    category: str
    kind: str
    tone: str
    mst: float
    tone_srgb: list
    offset: float
    seed: int
    index: int
    params: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return asdict(self)

    def fingerprint(self) -> str:
        """sha256 of everything that determines this entry's images (with the bake key and resolution)."""
        return hashlib.sha256(json.dumps(self.to_json(), sort_keys=True).encode()).hexdigest()

    def with_offset(self, offset: float) -> "Entry":
        return Entry(**{**self.to_json(), "offset": float(offset)})


def entry_seed(catalogue_seed: int, entry_id: str) -> int:
    """63-bit seed from (catalogue seed, id): independent of every other entry."""
    digest = hashlib.sha256(f"{int(catalogue_seed)}/{entry_id}".encode()).digest()
    return int.from_bytes(digest[:8], "little") & ((1 << 63) - 1)


def load_spec(path: str | Path | None = None) -> dict:
    """Read and validate a catalogue spec (schemas/texture_catalog_spec.schema.json); InputError on problems."""
    path = Path(path) if path is not None else default_spec_path()
    spec = read_json(path, "texture catalogue spec")
    validate_spec(spec, str(path))
    return spec


def validate_spec(spec: dict, source: str = "catalogue spec") -> None:
    """Check `spec` against the JSON Schema and the cross-field rules the schema cannot express."""
    check_schema(spec, "texture_catalog_spec.schema.json", source)
    for name, tone in spec["tones"].items():
        if not 1.0 <= tone <= len(spec["tone_scale"]["anchors_srgb"]):
            raise InputError(f"{source}: field 'tones.{name}' is {tone}, outside the tone scale")
    lo, hi = spec["offset"]
    if lo > hi:
        raise InputError(f"{source}: field 'offset' has min {lo} > max {hi}")
    if "default" in spec and spec["default"] not in {e.id for e in expand_catalog(spec)}:
        raise InputError(f"{source}: field 'default' {spec['default']!r} is not an id of the catalogue")


def expand_catalog(spec: dict) -> list[Entry]:
    """Every entry of the catalogue, overlays (per tone, in the spec's tone order) then base variations."""
    entries = []
    seed = spec["seed"]
    for tone in spec["tones"]:
        for category in OVERLAY_CATEGORIES:
            cat = spec["overlays"].get(category)
            for i in range(cat["count"] if cat else 0):
                entries.append(_entry(spec, seed, f"{tone}_{category}_{i:02d}", category, "overlay", tone, i))
    for category in BASE_CATEGORIES:
        cat = spec["base_variations"].get(category)
        for i in range(cat["count"] if cat else 0):
            entries.append(_entry(spec, seed, f"base_{category}_{i:02d}", category, "base_variation", None, i))
    return entries


# A positive offset on a light tone pushed its red past 1: 53 of 325 variants had over 20 % of their texels at
# red = 255 (linear albedo 1, brighter than any skin, detail lost, and any light blows them out). The offset is
# capped so the tone's brightest channel stays at or below this sRGB value (linear 0.79), or at its own value for
# the few tones already above it; the lighter texels of palms and nails then still fit under 1.
MAX_TONE_SRGB = 0.9


def _entry(spec, catalogue_seed, entry_id, category, kind, tone, index) -> Entry:
    s = entry_seed(catalogue_seed, entry_id)
    rng = np.random.default_rng([s, 0])
    if kind == "overlay":
        jitter = spec["tone_jitter"]
        mst = float(np.clip(spec["tones"][tone] + rng.uniform(-jitter, jitter), 1.0, 10.0))
        cat_spec, sampler = spec["overlays"][category], OVERLAYS[category][0]
    else:
        lo, hi = spec["base_variations"][category]["mst"]
        mst = float(rng.uniform(lo, hi))
        tone = min(spec["tones"], key=lambda t: abs(spec["tones"][t] - mst))
        cat_spec, sampler = spec["base_variations"][category], BASE_VARIATIONS[category][0]
    offset = float(rng.uniform(*spec["offset"]))
    params = {"skin": sample_base(rng, spec["skin"]), category: sampler(rng, cat_spec, index)}
    mst = round(mst, 5)
    srgb = color.linear_to_srgb(tone_rgb(spec, mst))
    offset = min(offset, max(0.0, MAX_TONE_SRGB - float(srgb.max())))
    return Entry(id=entry_id, category=category, kind=kind, tone=tone, mst=mst,
                 tone_srgb=[round(float(c), 6) for c in srgb], offset=round(offset, 5), seed=s, index=index,
                 params=_jsonable(params))


def _jsonable(obj):
    """Round-trip through JSON so params hold only plain types (as they will in catalog.json)."""
    return json.loads(json.dumps(obj))


def select(entries: list[Entry], ids=None, categories=None) -> list[Entry]:
    """The entries named by `ids` and/or in `categories` (all when both are empty), in catalogue order.
    Unknown ids or categories raise InputError."""
    if not ids and not categories:
        return list(entries)
    known_ids = {e.id for e in entries}
    known_cats = {e.category for e in entries}
    for i in ids or ():
        if i not in known_ids:
            raise InputError(f"texture id '{i}' is not in the catalogue (ids look like 'light_tattoos_07')")
    for c in categories or ():
        if c not in known_cats:
            raise InputError(f"texture category '{c}' is not in the catalogue; known: {', '.join(sorted(known_cats))}")
    ids, categories = set(ids or ()), set(categories or ())
    return [e for e in entries if e.id in ids or e.category in categories]


def tone_rgb(spec: dict, mst: float) -> np.ndarray:
    """Linear RGB (3,) of the spec's tone scale at `mst`."""
    return color.tone_color(mst, [color.hex_to_srgb(h) for h in spec["tone_scale"]["anchors_srgb"]])
