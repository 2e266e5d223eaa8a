"""A camera's image per dataset frame (dataset/film.py): 'none' renders what a run without films renders, byte for
byte; 'random' gives each frame its own film, recorded in its labels, the same on a second run; the labels other
than the film record are those of the clean run."""

from __future__ import annotations

import json

import pytest
from helpers_dataset import SIZE, files_of

from darthand.dataset.api import render_dataset
from darthand.dataset.film import film_setting, frame_film
from darthand.dataset.options import DatasetOptions
from darthand.errors import InputError
from darthand.render.film import Film


def _run(package, out, **kw):
    model, tex, acc = package
    return render_dataset(DatasetOptions(model, str(out), count=3, textures=tex, accessories=acc, size=SIZE,
                                         samples=4, processes=1, progress=False, **kw))


def _labels(folder) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted((folder / "labels").glob("*.json"))]


def test_none_is_exact_and_random_films_are_per_frame_recorded_and_deterministic(package, tmp_path):
    clean = _run(package, tmp_path / "clean")
    none = _run(package, tmp_path / "none", film="none")
    assert files_of(tmp_path / "clean") == files_of(tmp_path / "none") and "film" not in clean and "film" not in none
    first = _run(package, tmp_path / "a", film="random")
    _run(package, tmp_path / "b", film="random")
    assert first["film"] == {"random": True}
    assert files_of(tmp_path / "a") == files_of(tmp_path / "b")
    films = [labels["render"].pop("film") for labels in _labels(tmp_path / "a")]
    assert len({json.dumps(f, sort_keys=True) for f in films}) == 3 and len({f["seed"] for f in films}) == 3
    for developed, plain in zip(_labels(tmp_path / "a"), _labels(tmp_path / "clean")):
        developed["render"].pop("film")
        developed["render"]["dataset"].pop("job_sha256")
        plain["render"]["dataset"].pop("job_sha256")
        assert developed == plain
    clean_images = {k: v for k, v in files_of(tmp_path / "clean").items() if k.startswith("images/")}
    film_images = {k: v for k, v in files_of(tmp_path / "a").items() if k.startswith("images/")}
    assert clean_images.keys() == film_images.keys() and all(clean_images[k] != film_images[k] for k in clean_images)


def test_film_settings_of_a_run():
    assert film_setting("none") is None and film_setting(None) is None
    assert film_setting({"iso": 400}) == Film(iso=400).to_json()
    with pytest.raises(InputError, match="unknown film field"):
        film_setting({"grain": 1})
    with pytest.raises(InputError, match="no such film settings file"):
        film_setting("missing.json")
    job = {"index": 4, "pose": "fist"}
    assert frame_film({"random": True}, job) == frame_film({"random": True}, dict(job))
    assert frame_film({"random": True}, job) != frame_film({"random": True}, {**job, "index": 5})
    assert frame_film(None, job)[0] is None and frame_film({"iso": 400}, job)[0] == {"iso": 400}
    assert Film.from_json(frame_film({"random": True}, job)[0])               # the frame's draw is a film
