"""Camera views for datasets: directions uniform over the sphere by equal-area cells, roll, field of view, and the
hand's size in the image (or a distance range), never looking along the forearm.

Directions (from the hand toward the camera, in a right hand's frame; camera.frame_points mirrors them for a left
hand) cover the zone of the sphere outside a cone about +X (the forearm: seen from there the camera looks at the
wrist's cut end). On a sphere, x uniform and the angle about the x axis uniform give a uniform density (Archimedes'
hat-box theorem), so `bands` equal-height slabs of x in [-1, WRIST_CONE_COS] times `sectors` equal sectors of angle
are cells of equal area. Frame i falls into cell (offset + i * stride) mod n, stride coprime with n, so every run of
n consecutive frames visits every cell once; inside its cell the direction is uniform. The offset comes from the
seed. Over any number of frames the directions are uniform on the zone, and stratified (no clumps, no holes) over
every n frames.
"""

from __future__ import annotations

import math

import numpy as np

from darthand.errors import InputError
from darthand.model.preview import VIEWS

WRIST_CONE_COS = 0.8                # about 37 degrees about +X are excluded
BANDS, SECTORS = 8, 16              # 128 equal-area cells
RANDOM_VIEW = "random"
VIEW_STREAM = 3


def cell_count(bands: int = BANDS, sectors: int = SECTORS) -> int:
    return bands * sectors


def cell_stride(n: int) -> int:
    """A stride coprime with n near n * 0.382 (the golden section), so consecutive frames' cells lie far apart."""
    s = max(1, round(n * 0.381966))
    while math.gcd(s, n) != 1:
        s += 1
    return s


def frame_cell(seed: int, index: int, n: int) -> int:
    """The cell of frame `index`: (offset(seed) + index * stride) mod n."""
    offset = int(np.random.default_rng([seed, VIEW_STREAM]).integers(n))
    return (offset + int(index) * cell_stride(n)) % n


def cell_direction(cell: int, u: float, v: float, bands: int = BANDS, sectors: int = SECTORS,
                   cone_cos: float = WRIST_CONE_COS) -> list[float]:
    """A unit direction uniform inside `cell` for two uniforms u, v in [0, 1): x uniform in the cell's band of
    [-1, cone_cos], the angle about x uniform in its sector."""
    band, sector = divmod(int(cell), sectors)
    height = (1.0 + cone_cos) / bands
    x = -1.0 + height * (band + float(u))
    phi = 2 * math.pi * (sector + float(v)) / sectors
    r = math.sqrt(max(0.0, 1.0 - x * x))
    return [round(x, 6), round(r * math.cos(phi), 6), round(r * math.sin(phi), 6)]


def check_range(what: str, value, lo: float = -math.inf, hi: float = math.inf) -> tuple[float, float]:
    """(a, b) from a pair of finite numbers with lo <= a <= b <= hi; InputError naming `what` otherwise."""
    try:
        a, b = (float(x) for x in value)
    except (TypeError, ValueError):
        raise InputError(f"{what}: {value!r} is not a pair of numbers") from None
    if not (math.isfinite(a) and math.isfinite(b)):
        raise InputError(f"{what}: ({a}, {b}) must be finite")
    if not (lo <= a <= b <= hi):
        raise InputError(f"{what}: ({a}, {b}) must be ordered and within {lo}..{hi}")
    return a, b


class ViewSampler:
    """Per-frame camera specs (camera.load_camera's {"view": ...} form).

    views: 'random' and/or named views (preview.VIEWS), one drawn per frame; roll_deg, fov_deg: uniform ranges;
    margin: the free border (fraction of the image) when the camera is framed on the hand, uniform in its range;
    distance: a range of camera distances in metres instead, the hand then kept at least margin[0] from the border
    (the camera moves back when it would not fit)."""

    def __init__(self, views=None, *, roll_deg=(-45.0, 45.0), fov_deg=(30.0, 60.0), margin=(0.03, 0.15),
                 distance=None):
        names = [RANDOM_VIEW] if views is None else ([views] if isinstance(views, str) else list(views))
        for name in names:
            if name != RANDOM_VIEW and name not in VIEWS:
                raise InputError(f"views: {name!r} is not '{RANDOM_VIEW}' or a view ({', '.join(VIEWS)})")
        if not names:
            raise InputError("views: no view given")
        self.names = names
        self.roll = check_range("roll range", roll_deg, -180, 180)
        self.fov = check_range("field-of-view range", fov_deg, 1, 120)
        self.margin = check_range("margin range", margin, 0.0, 0.45)
        self.distance = None if distance is None else check_range("distance range", distance, 0.01, 100)

    def sample(self, seed: int, index: int, u: np.ndarray) -> tuple[dict, dict]:
        """(camera spec, record) of frame `index` from six uniforms u: view name, two for the direction, roll, fov,
        margin or distance."""
        name = self.names[min(int(u[0] * len(self.names)), len(self.names) - 1)]
        n = cell_count()
        record = {"view": name}
        if name == RANDOM_VIEW:
            cell = frame_cell(seed, index, n)
            view = cell_direction(cell, u[1], u[2])
            record["cell"] = cell
        else:
            view = name
        spec = {"view": view, "roll_deg": _lerp(self.roll, u[3], 2), "fov_deg": _lerp(self.fov, u[4], 3)}
        if self.distance is None:
            spec["margin"] = _lerp(self.margin, u[5], 4)
        else:
            spec["distance"], spec["margin"] = _lerp(self.distance, u[5], 4), self.margin[0]
        return spec, record


def _lerp(pair, u: float, digits: int) -> float:
    return round(float(pair[0] + (pair[1] - pair[0]) * float(u)), digits)
