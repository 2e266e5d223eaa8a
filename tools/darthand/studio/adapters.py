"""ADAPTERS (issue 28, studio branch): stand-ins for what the env and film branches are building, one function each,
written to the environment contract. The lead replaces each at merge with the function named in its docstring (and
deletes this module once all are replaced).

- builtin_environment_folder -> render/environment.list_builtin() (the vendored assets_src/environments/)
- read_map                   -> render/environment.read_map
- load_lighting_checked      -> render/lights.load_lighting (once the lights schema has the 'environment' field)
- environment_render_ready   -> always True (render/api draws a lights document's environment)
- environment_background_job -> the job background form the dataset planner uses for the environment backdrop
- check_film                 -> render/film.Film.from_json (its InputError for unknown or out-of-range fields)
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from darthand.errors import InputError
from darthand.processes import native_stderr_captured
from darthand.render.lights import load_lighting

REPO_ROOT = Path(__file__).resolve().parents[3]
VENDORED = REPO_ROOT / "assets_src" / "environments"
MAX_FILM_FIELDS = 32
NEGATIVE_NOISE = 0.05


def builtin_environment_folder() -> Path | None:
    """The folder of the built-in maps (<name>.exr): assets_src/environments/ once vendored, else Blender's own
    studio-light worlds in .venv-blender; None when neither exists."""
    if VENDORED.is_dir() and any(VENDORED.glob("*.exr")):
        return VENDORED
    found = sorted(REPO_ROOT.glob(".venv-blender/lib/python3*/site-packages/bpy/*/datafiles/studiolights/world"))
    return found[-1] if found else None


def read_map(path: Path) -> np.ndarray:
    """(H, W, 3) float32 linear radiance of an equirectangular map (a grey map's one channel repeated); InputError
    naming the file and the fault when it does not decode, is not 2:1, or holds NaN, Inf or negative values beyond
    NEGATIVE_NOISE x the map's mean (lossy EXR compression leaves texels slightly below 0 in 7 of Blender's 8 maps;
    those read as 0)."""
    with native_stderr_captured():
        buf = oiio.ImageBuf(str(path))
        pixels = buf.get_pixels(oiio.FLOAT) if buf.read(force=True) and not buf.has_error else None
    if pixels is None:
        reason = (buf.geterror() or "unknown format").strip().splitlines()
        raise InputError(f"{path}: environment map does not decode ({reason[0] if reason else 'unknown format'})")
    height, width = pixels.shape[:2]
    if width != 2 * height:
        raise InputError(f"{path}: environment map is {width}x{height}, not equirectangular (width = 2 x height)")
    pixels = pixels.reshape(height, width, -1)
    rgb = np.ascontiguousarray(np.repeat(pixels[..., :1], 3, axis=2) if pixels.shape[2] < 3 else pixels[..., :3],
                               np.float32)
    if not np.isfinite(rgb).all():
        raise InputError(f"{path}: environment map holds NaN or Inf values")
    if rgb.min() < -NEGATIVE_NOISE * max(float(rgb.mean()), 1e-6):
        raise InputError(f"{path}: environment map holds negative values (down to {rgb.min():.3g})")
    return np.maximum(rgb, 0)


def load_lighting_checked(doc: dict, what: str):
    """The lights document checked as render/lights.load_lighting does, its 'environment' field (checked by the
    studio) set aside until the lights schema carries it."""
    return load_lighting({k: v for k, v in doc.items() if k != "environment"}, what)


def environment_render_ready() -> bool:
    """Whether the renderer draws a lights document's environment (render/environment.py exists)."""
    return importlib.util.find_spec("darthand.render.environment") is not None


def environment_background_job(blur_deg: float) -> str | dict:
    """The job's background for 'the environment seen through the camera': the env branch's render_subject takes
    the string 'environment' (unblurred); blurred by blur_deg > 0 degrees, a spec {'environment': true, 'blur'} the
    frame path has yet to pass to background_view."""
    return "environment" if blur_deg == 0 else {"environment": True, "blur": float(blur_deg)}


def check_film(film, what: str) -> dict:
    """A film dict (render/film.Film's fields) checked for shape only: at most MAX_FILM_FIELDS fields, each a
    number, boolean, string, null or list of numbers (the film branch's parser checks names and ranges)."""
    if not isinstance(film, dict) or len(film) > MAX_FILM_FIELDS:
        raise InputError(f"{what}: field 'film' must be an object of at most {MAX_FILM_FIELDS} render/film.Film "
                         "fields")
    for name, value in film.items():
        values = value if isinstance(value, list) else [value]
        if not all(v is None or isinstance(v, (int, float, str, bool)) for v in values):
            raise InputError(f"{what}: field 'film.{name}' must be a number, boolean, string or list of numbers")
    return film
