"""A camera's image per dataset frame (render/film.py): the run's film setting, and each frame's film and noise
seed.

The setting (DatasetOptions.film) is 'none' (the renderer's own image, byte-identical to a run without films),
'random' (a plausible camera drawn per frame: `random_film`), or fixed settings (a FILM.json path or a dict of
render/film.Film's fields). A frame's draws (render/film.random_film) and its noise seed come from a hash of its
job, which is itself a function of (seed, index): frame i is the same on any machine, runner or shard.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np

from darthand.errors import InputError
from darthand.render import film as render_film

def film_setting(value) -> dict | None:
    """The run's film setting in the JSON form the workers get: None ('none'), {'random': True} ('random'), or a
    Film's to_json (a FILM.json path, a dict of its fields or a Film); InputError naming the file or field."""
    if value in (None, "none"):
        return None
    if value == "random":
        return {"random": True}
    if not isinstance(value, (str, dict, render_film.Film)):
        raise InputError(f"film: expected 'none', 'random', a FILM.json path or settings, got {value!r}")
    loaded = render_film.load_film(value)
    assert loaded is not None, "only 'none' loads as no film"
    return loaded.to_json()


def frame_film(setting: dict | None, job: dict) -> tuple[dict | None, int]:
    """(film settings or None, noise seed) of a frame: the run's fixed settings, or for 'random' a draw from
    numpy's Generator seeded with the job's hash; (None, 0) without a film (no noise to seed: the job's hash is
    not worked out)."""
    if setting is None:
        return None, 0
    seed = job_seed(job)
    if setting.get("random"):
        return render_film.random_film(np.random.default_rng([seed, 1]).random(render_film.RANDOM_UNIFORMS)), seed
    return setting, seed


def job_seed(job: dict) -> int:
    """A 63-bit seed from the job's canonical JSON (sha256)."""
    digest = hashlib.sha256(json.dumps(job, sort_keys=True).encode()).digest()
    return int.from_bytes(digest[:8], "big") >> 1
