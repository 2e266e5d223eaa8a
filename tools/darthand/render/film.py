"""A camera's image of the renderer's linear colour: exposure, optics, sensor, white balance, tone curve, JPEG.

`develop(colour, alpha, depth, film, seed)` turns a frame's linear colour into the 8-bit image a camera would have
written, in the order light meets a camera:

    exposure (x 2^EV)  ->  lens: chromatic aberration, defocus (depth-aware disc), motion (line), vignetting
    ->  sensor: shot noise + read noise (electrons, at an ISO)  ->  white balance error (per-channel gains)
    ->  tone curve (Hable's filmic curve, white point W)  ->  sRGB 8-bit  ->  JPEG round trip at quality Q

Exposure is metered from the light the scene receives, never from the hand's own brightness: `metered_white` is
what an incident-light meter at the hand reads under the frame's lights, its dome facing the camera (lights.py's
units: ambient + each light's radiance x the dome's response), and the automatic exposure scales it to
METERED_WHITE, its reading under the default light rig. So a dark hand stays dark and a light one light: the tone
its labels record is the tone its image shows, whatever the light's strength.

The tone curve is John Hable's filmic curve (Uncharted 2, GDC 2010; filmicworlds.com "Filmic Tonemapping
Operators"), with its published constants A..F, applied per channel and normalised by its white point W (the input
that maps to 1). Chosen over ACES fits (Narkowicz 2015, Hill) because it has an explicit white point and a nearly
linear toe: with exposure anchored at skin's reflectance (ANCHOR_ALBEDO), shadows and mid-tones keep the clean
render's sRGB codes within a few steps and only highlights are compressed (Narkowicz's fit darkens albedo 0.03 from
code 43 to 24 at the same anchor). Its curve: hable(x) = (x(Ax + CB) + DE) / (x(Ax + B) + DF) - E/F.

All maths in float32 linear light; the only randomness (sensor noise) comes from numpy's Generator seeded with
`seed`. The mask is not the image: `develop` returns the image only, and a frame's mask stays the geometry's
coverage; with blur on, the hand's edge in the image is softer and wider than the mask by up to the blur's radius.
"""

from __future__ import annotations

import io
import math
from dataclasses import asdict, dataclass, fields
from typing import Literal

import numpy as np
from scipy import ndimage, signal

from darthand.errors import InputError
from darthand.fileio import read_json
from darthand.render.environment import frame_environment
from darthand.render.image import encode_mask8
from darthand.render.lights import world_lights
from darthand.textures.color import encode_srgb8, luminance

# Hable's published constants: shoulder strength, linear strength, linear angle, toe strength, toe numerator and
# denominator.
HABLE_A, HABLE_B, HABLE_C, HABLE_D, HABLE_E, HABLE_F = 0.15, 0.50, 0.10, 0.20, 0.02, 0.30
HABLE_WHITE = 11.2             # Hable's own white point (his exposure bias of 2 is folded into our exposure)
DEFAULT_WHITE = 4.0            # ours: mid-tones within ~13 sRGB codes of the clean render up to albedo 0.8
METERED_WHITE = 0.92           # metered_white's luminance under the default light rig, on the camera's axis
CLEAN_WHITE = 0.72             # a white card facing the camera under the default rig: its clean render's radiance
ANCHOR_ALBEDO = 0.36           # skin's reflectance (one stop over 18 % grey): reproduced at its clean-render tone
# Automatic exposure stays within +-1.5 EV: a frame's background is an image the lights do not light, so a larger
# correction for a dim or back-lit hand would blow the background to white (and a scene without light is not
# amplified); a user who wants more sets exposure_ev.
AUTO_EV_LIMIT = 1.5
FULL_WELL_E = 10000.0          # electrons at the white point at ISO 100 (a small sensor's pixel)
BASE_ISO = 100.0
RECORD_ONLY = ("auto_exposure", "metered_white", "seed")   # what a record adds to the settings (Film.from_json)


@dataclass(frozen=True)
class Film:
    """A camera's image settings. exposure_ev: EV relative to the renderer's units (0: linear 1 stays 1 before the
    curve's anchoring), None for automatic (metered from the scene's light, see the module docstring);
    exposure_bias_ev: added to either. white_point: the tone curve's W (curve input that maps to white).
    white_balance: per-channel gains (R, G, B) of a white-balance error. iso: sensor gain (0: no sensor noise);
    read_noise: electrons. motion_blur_px, motion_blur_deg: a line kernel's length (pixels) and angle (degrees,
    counter-clockwise from the image's +x). defocus_px: blur disc radius (pixels) of a point at infinity with the
    hand in focus (0: all sharp). vignetting: the share of light lost at the image corners. chromatic_aberration_px:
    the red and blue channels' lateral shift at the corners (pixels, opposite ways). jpeg_quality: 0 none, else a
    JPEG round trip at that quality (1..100)."""

    exposure_ev: float | None = None
    exposure_bias_ev: float = 0.0
    white_point: float = DEFAULT_WHITE
    white_balance: tuple = (1.0, 1.0, 1.0)
    iso: float = 0.0
    read_noise: float = 3.0
    motion_blur_px: float = 0.0
    motion_blur_deg: float = 0.0
    defocus_px: float = 0.0
    vignetting: float = 0.0
    chromatic_aberration_px: float = 0.0
    jpeg_quality: int = 0

    def __post_init__(self):
        if self.exposure_ev is not None:
            _check_range(self.exposure_ev, "exposure_ev", -16, 16)
        _check_range(self.exposure_bias_ev, "exposure_bias_ev", -8, 8)
        _check_range(self.white_point, "white_point", 1.0, 64)
        gains = self.white_balance
        if not (isinstance(gains, (tuple, list)) and len(gains) == 3):
            raise InputError(f"film: field 'white_balance' must be three gains (R, G, B), got {gains!r}")
        for k, g in enumerate(gains):
            _check_range(g, f"white_balance.{k}", 0.25, 4)
        object.__setattr__(self, "white_balance", tuple(float(g) for g in gains))
        _check_range(self.iso, "iso", 0, 409600)
        if 0 < self.iso < 25:
            raise InputError(f"film: field 'iso' must be 0 (no noise) or at least 25, got {self.iso!r}")
        _check_range(self.read_noise, "read_noise", 0, 100)
        _check_range(self.motion_blur_px, "motion_blur_px", 0, 256)
        _check_range(self.motion_blur_deg, "motion_blur_deg", -360, 360)
        _check_range(self.defocus_px, "defocus_px", 0, 128)
        _check_range(self.vignetting, "vignetting", 0, 1)
        _check_range(self.chromatic_aberration_px, "chromatic_aberration_px", 0, 32)
        q = self.jpeg_quality
        if isinstance(q, bool) or not isinstance(q, (int, np.integer)) or not 0 <= q <= 100:
            raise InputError(f"film: field 'jpeg_quality' must be a whole number in 0..100, got {q!r}")

    def to_json(self) -> dict:
        doc = asdict(self)
        doc["white_balance"] = list(self.white_balance)
        return doc

    @classmethod
    def from_json(cls, doc, source: str = "film") -> "Film":
        """A Film from its dict (to_json's, or a frame's record: its RECORD_ONLY keys are ignored); InputError
        naming an unknown field."""
        if isinstance(doc, Film):
            return doc
        if not isinstance(doc, dict):
            raise InputError(f"{source}: expected an object of film settings, got {type(doc).__name__}")
        known = [f.name for f in fields(cls)]
        unknown = sorted(set(doc) - set(known) - set(RECORD_ONLY))
        if unknown:
            raise InputError(f"{source}: unknown film field {unknown[0]!r} (known: {', '.join(known)})")
        values = {k: v for k, v in doc.items() if k in known}
        if "white_balance" in values and isinstance(values["white_balance"], list):
            values["white_balance"] = tuple(values["white_balance"])
        try:
            return cls(**values)
        except InputError as e:
            raise InputError(f"{source}: {str(e).removeprefix('film: ')}") from None

    def with_exposure(self, ev: float) -> "Film":
        """The same film with exposure_ev set (the automatic exposure resolved)."""
        return Film(**{**asdict(self), "exposure_ev": float(ev)})


def _check_range(value, name: str, lo: float, hi: float) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not lo <= value <= hi:
        raise InputError(f"film: field '{name}' must be a number in {lo:g}..{hi:g}, got {value!r}")


# ------------------------------------------------------------------------------------------------ exposure


def metered_white(lighting, cam, point) -> np.ndarray:
    """(3,) float32 linear: what an incident-light meter at world `point` (3,) reads under `lighting`
    (lights.Lighting), its hemispherical dome facing the camera, in the renderer's radiance units (a white
    Lambertian card facing a light reflects its intensity): the ambient light plus each light's radiance x the
    dome's response (1 + cos theta) / 2 at the angle theta between the light and the camera (the dome's projected
    area: a light from the side counts half, as it lights half of a round subject), point lights with their
    inverse-square falloff; shadows ignored. An environment (lighting.environment) counts with its lights (the
    map's bright part) like the others and its remainder's irradiance on a card facing the camera."""
    point = np.asarray(point, np.float64)
    facing = cam.centre - point
    facing /= max(float(np.linalg.norm(facing)), 1e-12)
    total = np.asarray(lighting.ambient, np.float64).copy()
    lights = world_lights(lighting, cam.R, cam.t)
    if lighting.environment is not None:
        environment = frame_environment(lighting.environment, cam.R)
        lights = lights + environment.lights
        total += environment.irradiance(facing[:, None])[:, 0]
    for light in lights:
        if light["type"] == "directional":
            toward, scale = -np.asarray(light["direction"]), 1.0
        else:
            offset = np.asarray(light["position"]) - point
            distance = max(float(np.linalg.norm(offset)), 1e-6)
            toward, scale = offset / distance, 1.0 / distance ** 2
        total += np.asarray(light["radiance"], np.float64) * scale * 0.5 * (1.0 + float(toward @ facing))
    return total.astype(np.float32)


def auto_exposure_ev(white: np.ndarray) -> float:
    """EV that brings a metered white's luminance to METERED_WHITE (within +-AUTO_EV_LIMIT)."""
    y = float(luminance(np.asarray(white, np.float32)))
    ev = math.log2(METERED_WHITE / y) if y > 0 else AUTO_EV_LIMIT
    return float(np.clip(ev, -AUTO_EV_LIMIT, AUTO_EV_LIMIT))


def exposure_scale(film: Film) -> float:
    """The factor on linear colour before the tone curve: 2^(exposure_ev + bias) times the factor that puts
    ANCHOR_ALBEDO x CLEAN_WHITE (a skin-like surface facing the camera under the default rig) where the clean render
    shows it (tone_curve(k x) = x at that value). exposure_ev None counts as 0 (resolve it with `with_exposure`)."""
    anchor = ANCHOR_ALBEDO * CLEAN_WHITE
    ev = (film.exposure_ev or 0.0) + film.exposure_bias_ev
    return float(inverse_tone_curve(anchor, film.white_point) / anchor * 2.0 ** ev)


# ------------------------------------------------------------------------------------------------ tone curve


def hable(x):
    """Hable's filmic curve (unnormalised) of linear x >= 0."""
    A, B, C, D, E, F = HABLE_A, HABLE_B, HABLE_C, HABLE_D, HABLE_E, HABLE_F
    return (x * (A * x + C * B) + D * E) / (x * (A * x + B) + D * F) - E / F


def tone_curve(x, white: float = DEFAULT_WHITE):
    """Linear x >= 0 -> display-linear [0, 1]: hable(x) / hable(white), clipped (inputs above white clip)."""
    x = np.maximum(x, 0)
    return np.minimum(hable(x) / hable(white), 1)


def inverse_tone_curve(y: float, white: float = DEFAULT_WHITE) -> float:
    """The x in [0, white] with tone_curve(x, white) = y (y in [0, 1]): the root of a quadratic."""
    A, B, C, D, E, F = HABLE_A, HABLE_B, HABLE_C, HABLE_D, HABLE_E, HABLE_F
    h = float(np.clip(y, 0, 1)) * float(hable(white)) + E / F        # (x(Ax + CB) + DE) = h (x(Ax + B) + DF)
    a, b, c = A * (1 - h), C * B - h * B, D * E - h * D * F
    if abs(a) < 1e-12:
        return -c / b
    return float((-b + math.sqrt(b * b - 4 * a * c)) / (2 * a))


# ------------------------------------------------------------------------------------------------ lens


def disc_kernel(radius: float) -> np.ndarray:
    """(2R+1, 2R+1) float32 disc of `radius` pixels with an anti-aliased rim, summing to 1 (radius < 0.5: a
    delta)."""
    R = int(math.ceil(radius + 0.5))
    y, x = np.mgrid[-R:R + 1, -R:R + 1]
    k = np.clip(radius + 0.5 - np.hypot(x, y), 0, 1).astype(np.float32)
    k[R, R] = max(k[R, R], 1e-6)
    return k / k.sum()


def line_kernel(length: float, angle_deg: float) -> np.ndarray:
    """(2R+1, 2R+1) float32 motion kernel: a segment of `length` pixels through the centre at `angle_deg`
    (counter-clockwise from +x, image y down), points along it splatted bilinearly; sums to 1."""
    R = int(math.ceil(length / 2)) + 1
    k = np.zeros((2 * R + 1, 2 * R + 1), np.float64)
    n = max(2, int(math.ceil(4 * length)) + 1)
    s = ((np.arange(n) + 0.5) / n - 0.5) * length         # midpoints of n equal parts: a uniform segment
    a = math.radians(angle_deg)
    x, y = R + s * math.cos(a), R - s * math.sin(a)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    for dx, dy, w in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(k, (y0 + dy, x0 + dx), w)
    return (k / k.sum()).astype(np.float32)


def convolve(image: np.ndarray, kernel: np.ndarray, mode: Literal["reflect", "constant"] = "reflect") -> np.ndarray:
    """(H, W, C) float32 image convolved with an odd square kernel (FFT), the border extended by numpy.pad's
    `mode` ('reflect': the frame's content continues; 'constant': zeros)."""
    R = kernel.shape[0] // 2
    if R == 0:
        return image * kernel[0, 0]
    padded = np.pad(image, ((R, R), (R, R), (0, 0)), mode=mode)
    out = signal.fftconvolve(padded, kernel[:, :, None], mode="valid", axes=(0, 1))
    return out.astype(np.float32)


def blur_by_radius(image: np.ndarray, radius: np.ndarray, weight: np.ndarray | None = None) -> np.ndarray:
    """(H, W, C) image blurred by a disc whose radius (H, W) pixels varies per pixel: the image blurred at a few
    radii (0, 0.5, 1, 2, 4, ...: each level double the last) and each pixel interpolated between the two levels
    around its radius (a gather: an output pixel sees its own radius). weight (H, W): normalised convolution
    (sum of k w image / sum of k w), for a layer that has pixels only where weight > 0 (a background behind the
    hand); None: plain convolution."""
    top = float(radius.max()) if radius.size else 0.0
    if radius.size and top == float(radius.min()):          # one radius: one convolution
        return _blur_at(image, top, weight)
    levels = [0.0] + [0.5 * 2 ** k for k in range(int(math.ceil(math.log2(max(top, 0.5) / 0.5))) + 1)]
    lo = np.zeros(image.shape, np.float32)
    out = np.zeros(image.shape, np.float32)
    previous = None
    for k, level in enumerate(levels):
        blurred = _blur_at(image, level, weight)
        if previous is None:
            lo = blurred
            out[:] = blurred
        else:
            span = levels[k] - levels[k - 1]
            t = np.clip((radius - levels[k - 1]) / span, 0, 1)[..., None]
            inside = (radius > levels[k - 1])[..., None]
            out = np.where(inside, (1 - t) * lo + t * blurred, out)
            lo = blurred
        previous = level
    return out


def _blur_at(image: np.ndarray, radius: float, weight: np.ndarray | None) -> np.ndarray:
    """image (H, W, C) convolved with disc_kernel(radius), normalised by the convolved weight (H, W) if given."""
    if weight is None:
        return convolve(image, disc_kernel(radius))
    C = image.shape[2]
    both = convolve(np.concatenate([image * weight[..., None], weight[..., None]], axis=2), disc_kernel(radius),
                    "constant")
    return both[..., :C] / np.maximum(both[..., C:], 1e-6)


def defocus(premult: np.ndarray, alpha: np.ndarray, depth: np.ndarray, background: np.ndarray | None,
            radius_at_infinity: float) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(premult, alpha, background) blurred for a lens focused on the hand's median depth z_focus: a point at
    depth z gets a disc of radius radius_at_infinity x |1 - z_focus / z| (a thin lens), the background (H, W, 3)
    or None, known where alpha is 0, at infinity (or at its depth where it carries one). premult (H, W, 3) and
    alpha (H, W) are the hand layer."""
    hand = (alpha > 0.5) & (depth > 0)
    if not hand.any() or radius_at_infinity <= 0:
        return premult, alpha, background
    focus = float(np.median(depth[hand]))
    with np.errstate(divide="ignore", invalid="ignore"):
        radius = np.where(depth > 0, radius_at_infinity * np.abs(1 - focus / depth), radius_at_infinity)
    radius = np.minimum(radius, 4 * radius_at_infinity).astype(np.float32)
    on_hand = np.where((alpha > 0) & (depth > 0), radius, 0)     # an edge pixel whose centre missed: in focus
    layer = np.concatenate([premult, alpha[..., None]], axis=2)
    box = _around(alpha > 0, int(math.ceil(float(on_hand.max()))) + 2)   # the layer is empty outside it
    layer[box] = blur_by_radius(layer[box], on_hand[box])
    if background is not None:
        background = blur_by_radius(background, np.where(alpha > 0, radius_at_infinity, radius),
                                    (alpha <= 0).astype(np.float32))
    return layer[..., :3], layer[..., 3], background


def _around(mask: np.ndarray, margin: int) -> tuple[slice, slice]:
    """The rows and columns of mask's true pixels' bounding box grown by `margin`, within the image."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    H, W = mask.shape
    return (slice(max(0, rows[0] - margin), min(H, rows[-1] + 1 + margin)),
            slice(max(0, cols[0] - margin), min(W, cols[-1] + 1 + margin)))


def chromatic_aberration(image: np.ndarray, shift_px: float) -> np.ndarray:
    """(H, W, 3) lateral chromatic aberration: red magnified and blue shrunk about the image centre so that each
    moves `shift_px` pixels at the corners (bilinear resampling, edges extended)."""
    H, W, _ = image.shape
    half_diagonal = 0.5 * math.hypot(H, W)
    y, x = np.mgrid[0:H, 0:W].astype(np.float32)
    cy, cx = (H - 1) / 2, (W - 1) / 2
    out = image.copy()
    for channel, sign in ((0, 1.0), (2, -1.0)):
        scale = 1.0 / (1.0 + sign * shift_px / half_diagonal)    # sample nearer the centre: the channel grows
        coords = [cy + (y - cy) * scale, cx + (x - cx) * scale]
        out[..., channel] = ndimage.map_coordinates(image[..., channel], coords, order=1, mode="nearest")
    return out


def vignette(image: np.ndarray, strength: float) -> np.ndarray:
    """(H, W, C) image x (1 - strength rho^2), rho the distance from the centre over the half diagonal (the
    small-angle form of the cos^4 law)."""
    H, W = image.shape[:2]
    y, x = np.ogrid[0:H, 0:W]
    rho2 = ((y - (H - 1) / 2) ** 2 + (x - (W - 1) / 2) ** 2) / (0.25 * (H * H + W * W))
    return image * (1 - strength * rho2).astype(np.float32)[..., None]


# ------------------------------------------------------------------------------------------------ sensor


def electrons_per_unit(film: Film) -> float:
    """Electrons per unit of exposed linear signal: FULL_WELL_E at the white point at BASE_ISO, fewer at higher
    ISO (the same image brightness from less light)."""
    return FULL_WELL_E / film.white_point * BASE_ISO / film.iso


def noise_sigma(signal_level, film: Film):
    """Standard deviation of the sensor noise on an exposed linear signal: sqrt(s / c + (read / c)^2), c =
    electrons_per_unit (Poisson shot noise in electrons plus Gaussian read noise, back in signal units)."""
    c = electrons_per_unit(film)
    return np.sqrt(np.maximum(signal_level, 0) / c + (film.read_noise / c) ** 2)


def sensor_noise(image: np.ndarray, film: Film, rng: np.random.Generator) -> np.ndarray:
    """image + Gaussian noise of noise_sigma per pixel and channel (the shot noise's Gaussian limit, exact in mean
    and variance); unchanged at iso 0."""
    if film.iso <= 0:
        return image
    noise = rng.standard_normal(image.shape, dtype=np.float32)
    return (image + noise * noise_sigma(image, film).astype(np.float32)).astype(np.float32)


# ------------------------------------------------------------------------------------------------ output


def jpeg_round_trip(rgb: np.ndarray, quality: int) -> np.ndarray:
    """(H, W, 3) uint8 after encoding as JPEG at `quality` (Pillow's libjpeg, 4:2:0) and decoding; deterministic."""
    from PIL import Image  # lazy: only frames with JPEG on pay Pillow's import

    buffer = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb, np.uint8), "RGB").save(buffer, "JPEG", quality=int(quality))
    buffer.seek(0)
    with Image.open(buffer) as decoded:
        return np.asarray(decoded.convert("RGB"), np.uint8)


def develop(colour: np.ndarray, alpha: np.ndarray, depth: np.ndarray, film: Film, seed: int, *,
            composited: bool = True, background: np.ndarray | None = None) -> np.ndarray:
    """(H, W, 4) uint8 sRGB image of a frame through `film` (module docstring: the steps and their order).

    colour (H, W, 3) float32 linear: composited over a background (composited=True) or premultiplied by alpha (no
    background); alpha (H, W) float32 the hand and accessory's coverage; depth (H, W) float32 camera z in metres,
    0 where nothing was hit (the background, taken at infinity); seed: the sensor noise's Generator seed.
    film.exposure_ev None counts as 0 EV (resolve the automatic exposure first: metered_white, auto_exposure_ev,
    Film.with_exposure). Output alpha: 255 when composited, else the coverage (encode_mask8) with straight colour:
    the mask, never blurred, is the geometry's coverage. background (H, W, 3) linear: the composited frame's
    background, if known, for defocus to separate the hand from it exactly (else estimated from the uncovered
    pixels around each edge pixel)."""
    rng = np.random.default_rng(int(seed))
    alpha = np.asarray(alpha, np.float32)
    image = np.asarray(colour, np.float32) * np.float32(exposure_scale(film))
    if film.chromatic_aberration_px > 0:
        image = chromatic_aberration(image, film.chromatic_aberration_px)
    behind = None if background is None else np.asarray(background, np.float32) * np.float32(exposure_scale(film))
    image, cover = _blur(image, alpha, np.asarray(depth, np.float32), film, composited, behind)
    if film.vignetting > 0:
        image = vignette(image, film.vignetting)
    if not composited:
        image = np.where(cover[..., None] > 1e-6, image / np.maximum(cover, 1e-6)[..., None], 0).astype(np.float32)
    image = sensor_noise(image, film, rng)
    image = image * np.asarray(film.white_balance, np.float32)
    rgb = encode_srgb8(tone_curve(image, film.white_point).astype(np.float32))
    if film.jpeg_quality:
        rgb = jpeg_round_trip(rgb, film.jpeg_quality)
    a8 = np.full(alpha.shape, 255, np.uint8) if composited else encode_mask8(alpha)
    return np.concatenate([rgb, a8[..., None]], axis=2)


def _blur(image, alpha, depth, film: Film, composited: bool, known=None) -> tuple[np.ndarray, np.ndarray]:
    """(image, the image's own coverage) after defocus then motion blur. Composited frames are split into the hand
    layer and the background behind it (the background under the hand filled from its surroundings), blurred
    apart and composited again; a premultiplied frame is the hand layer alone. known: the exposed background, when
    given."""
    cover = alpha
    if film.defocus_px > 0:
        background = None
        if composited:
            behind = (alpha <= 0).astype(np.float32)
            nearby = _blur_at(image, 1.5, behind) if known is None else known    # what the edge pixels cover
            background = np.where(behind[..., None] > 0, image, nearby)
            hand = np.maximum(image - (1 - alpha)[..., None] * nearby, 0)       # the hand layer, premultiplied
            image = np.where(behind[..., None] > 0, 0, hand).astype(np.float32)
        image, cover, background = defocus(image, alpha, depth, background, film.defocus_px)
        if background is not None:
            image = image + (1 - np.clip(cover, 0, 1))[..., None] * background
            cover = alpha
    if film.motion_blur_px > 0:
        kernel = line_kernel(film.motion_blur_px, film.motion_blur_deg)
        if composited:
            image = convolve(image, kernel)
        else:
            both = convolve(np.concatenate([image, cover[..., None]], axis=2), kernel)
            image, cover = both[..., :3], both[..., 3]
    return image, cover


def develop_frame(colour, alpha, depth, film: Film, seed: int, lighting, cam, point,
                  background: np.ndarray | None) -> tuple[np.ndarray, dict]:
    """(rgba, record) of a rendered frame through `film`, its automatic exposure metered at world `point` (the
    hand's centre) under `lighting` seen by `cam` (metered_white). record: the film applied (exposure resolved),
    whether its exposure was automatic, the metered white (linear RGB) and the noise seed: what labels carry
    (Film.from_json reads it back). background: the composited background (H, W, 3) linear, or None."""
    white = metered_white(lighting, cam, point)
    auto = film.exposure_ev is None
    applied = film.with_exposure(auto_exposure_ev(white)) if auto else film
    rgba = develop(colour, alpha, depth, applied, seed, composited=background is not None, background=background)
    record = {**applied.to_json(), "auto_exposure": auto, "metered_white": [round(float(v), 6) for v in white],
              "seed": int(seed)}
    return rgba, record


# ------------------------------------------------------------------------------------------------ a random camera

RANDOM_UNIFORMS = 16       # random_film's uniforms, each with a fixed role (a new draw takes a new index)


def random_film(u: np.ndarray) -> dict:
    """A plausible camera's film settings (Film.to_json's dict) from RANDOM_UNIFORMS uniforms in [0, 1): automatic
    exposure with a bias in -0.7..+0.5 EV, white point 3..8, white balance errors within +-8 % on red and blue,
    ISO 100..3200 (log-uniform) with 1.5..6 e- read noise, vignetting up to 0.35; in a share of frames each: motion
    blur (15 %, 1..8 px at any angle), defocus (10 %, 1..5 px at infinity), chromatic aberration (10 %, 0.3..1.5
    px), JPEG (60 %, quality 50..95). Pixel sizes are for frames of a few hundred pixels a side. The blurs' shares
    are what a dataset can afford (benchmarks/film.py: at 512^2 defocus costs ~110 ms, aberration ~33 ms, motion
    blur ~26 ms, the rest ~40 ms) and the environment backdrop is out of focus already."""
    u = np.asarray(u, np.float64)
    if u.shape != (RANDOM_UNIFORMS,):
        raise ValueError(f"random_film takes {RANDOM_UNIFORMS} uniforms, got shape {u.shape}")
    between = lambda k, lo, hi: round(float(lo + (hi - lo) * u[k]), 4)
    sometimes = lambda k, share, value: value if u[k] < share else 0.0
    film = Film(
        exposure_ev=None, exposure_bias_ev=between(0, -0.7, 0.5), white_point=between(1, 3.0, 8.0),
        white_balance=(round(math.exp(between(2, -0.08, 0.08)), 4), 1.0, round(math.exp(between(3, -0.08, 0.08)), 4)),
        iso=round(100.0 * 32.0 ** float(u[4]), 1), read_noise=between(5, 1.5, 6.0),
        motion_blur_px=sometimes(6, 0.15, between(7, 1.0, 8.0)), motion_blur_deg=between(8, 0.0, 180.0),
        defocus_px=sometimes(9, 0.1, between(10, 1.0, 5.0)), vignetting=between(11, 0.0, 0.35),
        chromatic_aberration_px=sometimes(12, 0.1, between(13, 0.3, 1.5)),
        jpeg_quality=int(50 + min(int(u[15] * 46), 45)) if u[14] < 0.6 else 0)
    return film.to_json()


def load_film(spec, seed: int = 0) -> Film | None:
    """A Film from 'none' or None (no film), 'random' (random_film drawn from numpy's Generator seeded with
    `seed`), a FILM.json path or a dict of its fields; InputError naming the file or field."""
    if spec is None or isinstance(spec, Film):
        return spec
    if isinstance(spec, dict):
        return Film.from_json(spec)
    if spec == "none":
        return None
    if spec == "random":
        return Film.from_json(random_film(np.random.default_rng(int(seed)).random(RANDOM_UNIFORMS)))
    return Film.from_json(read_json(spec, "film settings file (or 'none', 'random')"), str(spec))
