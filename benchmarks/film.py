"""A camera's image (render/film.py): CPU per frame of each element, at 256^2 and 512^2.

One frame of the open hand (three-quarter view, over a built-in background) is rendered at each size; `develop`
then runs on its colour, coverage and depth with the tone curve alone (exposure, Hable's curve, 8-bit sRGB: the
base every film pays) and with each element added alone, and with a busy camera (all elements) and random films
(random_film, the dataset's 'random'). Figures: best-of-REPEATS CPU ms (time.process_time, one process; scipy's FFT
runs single-threaded here), and for each element what it adds to the base.
"""

from __future__ import annotations

import os
import time

import numpy as np

SIZES = (256, 512)
REPEATS = 3
ELEMENTS = {
    "base (exposure + tone curve + sRGB)": {},
    "sensor noise (ISO 1600)": {"iso": 1600.0},
    "white balance": {"white_balance": (1.06, 1.0, 0.94)},
    "vignetting": {"vignetting": 0.3},
    "chromatic aberration (1 px)": {"chromatic_aberration_px": 1.0},
    "motion blur (8 px)": {"motion_blur_px": 8.0, "motion_blur_deg": 30.0},
    "defocus (4 px at infinity)": {"defocus_px": 4.0},
    "JPEG (quality 75)": {"jpeg_quality": 75},
    "all of them": {"iso": 1600.0, "white_balance": (1.06, 1.0, 0.94), "vignetting": 0.3,
                    "chromatic_aberration_px": 1.0, "motion_blur_px": 8.0, "motion_blur_deg": 30.0,
                    "defocus_px": 4.0, "jpeg_quality": 75},
}


def frame_at(size: int):
    """(colour, alpha, depth, background) of one rendered frame of the open hand at size^2."""
    from darthand.dataset.backgrounds import builtin_background, crop
    from darthand.render.api import Renderer, open_source

    spec = {"zoom": 1.0, "centre": [0.5, 0.5], "flip": False, "builtin": 2}
    background = crop(builtin_background(2), spec, size, size)
    frame = Renderer(open_source("open"), 1).render("fist", width=size, height=size, background=background,
                                                    labels=False)
    return frame.colour, frame.alpha, frame.depth, background


def develop_ms(inputs, film) -> float:
    """Best-of-REPEATS CPU ms of develop on a frame's inputs."""
    from darthand.render.film import develop

    colour, alpha, depth, background = inputs
    best = np.inf
    for k in range(REPEATS + 1):
        c = time.process_time()
        develop(colour, alpha, depth, film, k, background=background)
        if k:                                    # the first call warms caches and compiled kernels
            best = min(best, time.process_time() - c)
    return round(1000 * float(best), 2)


def run() -> dict:
    from darthand.render.film import RANDOM_UNIFORMS, Film, random_film

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    result: dict = {"repeats": REPEATS, "sizes": list(SIZES), "cpu_ms": {}, "added_ms": {}}
    rng = np.random.default_rng(0)
    randoms = [Film.from_json(random_film(rng.random(RANDOM_UNIFORMS))).with_exposure(0.0) for _ in range(8)]
    for size in SIZES:
        inputs = frame_at(size)
        ms = {name: develop_ms(inputs, Film(exposure_ev=0.0, **fields)) for name, fields in ELEMENTS.items()}
        ms["random films (mean of 8)"] = round(float(np.mean([develop_ms(inputs, f) for f in randoms])), 2)
        base = ms["base (exposure + tone curve + sRGB)"]
        result["cpu_ms"][str(size)] = ms
        result["added_ms"][str(size)] = {k: round(v - base, 2) for k, v in ms.items() if not k.startswith("base")}
    return result


def summary(res: dict) -> str:
    sizes = [str(s) for s in res["sizes"]]
    lines = ["CPU ms per frame of `develop` (best of "
             f"{res['repeats']}, one process), and what each element adds to the base.", "",
             "| element | " + " | ".join(f"{s}^2 ms | {s}^2 added" for s in sizes) + " |",
             "|---|" + "---|---|" * len(sizes)]
    for name in res["cpu_ms"][sizes[0]]:
        cells = []
        for s in sizes:
            cells += [f"{res['cpu_ms'][s][name]:.1f}", f"{res['added_ms'][s].get(name, 0.0):.1f}"]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
